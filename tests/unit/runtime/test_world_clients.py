"""pybullet clients: made when a world first needs one (a world of boxes over the plane casts
its rays without); reused (`world.CLIENTS`): a world on a reset client is the world on a
new one: body ids from 0, the same render, the same ray casts, nothing left of the world
before; at most `MAX` idle; a forked process does not take its parent's."""

from __future__ import annotations

import numpy as np

from addt_dsl.runtime import world as W
from addt_dsl.runtime.world import PhysicsWorld


def _scene(w: PhysicsWorld) -> tuple:
    w.add_box("ego", 4.5, 1.9, 1.5, rgba=(0.2, 0.3, 0.8, 1.0))
    w.add_box("lead", 4.5, 1.9, 1.5, rgba=(0.8, 0.2, 0.2, 1.0))
    w.set_pose("ego", 0.0, 0.0, 0.75, 0.0)
    w.set_pose("lead", 12.0, 0.5, 0.75, 0.1)
    view = w.p.computeViewMatrix([-6.0, 0.0, 2.0], [10.0, 0.0, 1.0], [0.0, 0.0, 1.0])
    proj = w.p.computeProjectionMatrixFOV(60.0, 4 / 3, 0.1, 100.0)
    rgb, z, ids = w.render(64, 48, view, proj)
    starts = np.tile([0.0, 0.0, 1.0], (90, 1))
    ang = np.linspace(-0.6, 0.6, 90)
    ends = starts + 40.0 * np.stack([np.cos(ang), np.sin(ang), -0.02 * np.ones(90)], axis=1)
    w.analytic_rays = False  # pybullet's own caster: what the client holds
    hit, frac = w.ray_cast(starts, ends)
    return dict(w.bodies), rgb.tobytes(), z.tobytes(), ids.tobytes(), hit.tolist(), frac.tobytes()


def test_reset_client_gives_the_new_clients_world(monkeypatch):
    monkeypatch.setattr(W, "CLIENTS", W._Clients())
    fresh = PhysicsWorld(visual=True)
    want = _scene(fresh)
    fresh.close()
    assert len(W.CLIENTS.idle) == 1
    other = PhysicsWorld(visual=True)  # another scene on the reused client
    other.add_box("truck", 10.0, 2.5, 3.5, rgba=(0.1, 0.9, 0.1, 1.0))
    other.set_pose("truck", 8.0, -1.0, 1.75, 0.4)
    other.close()
    again = PhysicsWorld(visual=True)
    assert again.client == fresh.client or not W.CLIENTS.idle
    assert _scene(again) == want
    again.close()


def test_pool_bounded_and_not_inherited(monkeypatch):
    pool = W._Clients()
    monkeypatch.setattr(W, "CLIENTS", pool)
    monkeypatch.setattr(W._Clients, "MAX", 2)
    worlds = [PhysicsWorld() for _ in range(3)]
    assert len({w.client for w in worlds}) == 3  # (asked: made)
    for w in worlds:
        w.close()
    assert len(pool.idle) == 2  # the third disconnected
    pool.pid = -1  # as seen from a forked child: its parent's clients are not taken
    assert pool.take() is None and pool.idle == []
    w = PhysicsWorld()
    assert w.client is not None
    w.close()
    import pybullet

    for c in pool.idle:
        pybullet.disconnect(physicsClientId=c)
    pool.idle.clear()


def test_a_world_makes_its_client_only_when_asked(monkeypatch):
    """Analytic ray casts need no client; the first pybullet query makes one and hands it
    the bodies made before, in order and posed as last set: the answers of a world that had
    its client from the start."""
    monkeypatch.setattr(W, "CLIENTS", W._Clients())
    lazy = PhysicsWorld()
    ids = [lazy.add_box(n, 4.5, 1.9, 1.5) for n in ("ego", "lead", "truck")]
    assert ids == [1, 2, 3] and lazy.ground == 0
    lazy.set_pose("lead", 12.0, 0.5, 0.75, 0.1)
    lazy.set_poses(np.array([2], dtype=np.intp), np.array([[20.0], [-1.0], [0.75], [0.3], [0.0]]), 0,
                   np.arange(5, dtype=np.int64))  # (x, y, z, heading, pitch rows of a table, column 0)
    lazy.set_ground_height(-0.5)
    starts = np.tile([0.0, 0.0, 1.0], (90, 1))
    ang = np.linspace(-0.6, 0.6, 90)
    ends = starts + 40.0 * np.stack([np.cos(ang), np.sin(ang), -0.05 * np.ones(90)], axis=1)
    analytic = lazy.ray_cast(starts, ends, ignore="ego")
    assert not lazy.connected  # nothing asked pybullet yet
    eager = PhysicsWorld()
    assert eager.client is not None  # made first, then the same bodies and poses
    for n in ("ego", "lead", "truck"):
        eager.add_box(n, 4.5, 1.9, 1.5)
    eager.set_pose("lead", 12.0, 0.5, 0.75, 0.1)
    eager.set_pose("truck", 20.0, -1.0, 0.75, 0.3)
    eager.set_ground_height(-0.5)
    lazy.analytic_rays = eager.analytic_rays = False
    hit, frac = lazy.ray_cast(starts, ends, ignore="ego")
    assert lazy.connected
    want_hit, want_frac = eager.ray_cast(starts, ends, ignore="ego")
    assert hit.tolist() == want_hit.tolist() and frac.tobytes() == want_frac.tobytes()
    assert set(hit.tolist()) == {-1, 2, 3} and hit.tolist() == analytic[0].tolist()
    assert np.allclose(frac, analytic[1], atol=1e-6)
    lazy.close()
    eager.close()


def test_boxes_added_at_once_are_the_boxes_added_one_by_one(monkeypatch):
    """`add_boxes` against `add_box` in turn (the same ids, names, slots, tables and ray casts)
    and against the tables written out, on a world with and without a client, boxes added
    before and after the call."""
    monkeypatch.setattr(W, "CLIENTS", W._Clients())
    boxes = [("lead", 4.5, 1.9, 1.5, (0.8, 0.2, 0.2, 1.0)), ("truck", 9.0, 2.5, 3.2, None),
             ("bike", 1.8, 0.6, 1.4, (0.1, 0.1, 0.1, 1.0))]
    starts = np.tile([0.0, 0.0, 1.0], (90, 1))
    ang = np.linspace(-0.6, 0.6, 90)
    ends = starts + 40.0 * np.stack([np.cos(ang), np.sin(ang), -0.05 * np.ones(90)], axis=1)
    for eager in (False, True):
        one, many = PhysicsWorld(), PhysicsWorld()
        if eager:
            assert one.client is not None and many.client is not None
        one.add_box("ego", 4.5, 1.9, 1.5)
        many.add_box("ego", 4.5, 1.9, 1.5)
        ids = [one.add_box(*b) for b in boxes]
        assert many.add_boxes(boxes) == ids == [2, 3, 4]
        assert many.add_boxes([]) == []
        one.add_box("last", 3.0, 1.5, 1.2)
        many.add_box("last", 3.0, 1.5, 1.2)
        for w in (one, many):
            w.set_pose("truck", 20.0, -1.0, 1.6, 0.3)
            w.set_pose("bike", 9.0, 1.0, 0.7, -0.2)
        assert one.bodies == many.bodies and one.body_names == many.body_names
        # The tables written out: a row per box in the order added, unposed ones where made.
        sizes = [(4.5, 1.9, 1.5), *[b[1:4] for b in boxes], (3.0, 1.5, 1.2)]
        scene = many.ray_scene()
        assert scene[2].tolist() == [[l / 2, w / 2, h / 2] for l, w, h in sizes]
        assert scene[5].tolist() == [1, 2, 3, 4, 5, many.ground, -1]
        assert many.box_poses()[[0, 1, 4]].tolist() == [[0.0, 0.0, h / 2, 0.0, 0.0] for _, _, h in
                                                        (sizes[0], sizes[1], sizes[4])]
        assert one.box_slots(list(one.bodies)) == many.box_slots(list(many.bodies))
        assert one.box_poses().tobytes() == many.box_poses().tobytes()
        a, b = one.ray_scene(), many.ray_scene()
        for x, y in zip(a, b):
            assert np.asarray(x).tobytes() == np.asarray(y).tobytes() and np.asarray(x).dtype == np.asarray(y).dtype
        for analytic in (True, False):
            one.analytic_rays = many.analytic_rays = analytic
            hit, frac = one.ray_cast(starts, ends, ignore="ego")
            got_hit, got_frac = many.ray_cast(starts, ends, ignore="ego")
            assert hit.tolist() == got_hit.tolist() and frac.tobytes() == got_frac.tobytes()
            assert {3, 4} <= set(hit.tolist())
        one.close()
        many.close()
