"""Reused pybullet clients (`world.CLIENTS`): a world on a reset client is the world on a
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
    for w in worlds:
        w.close()
    assert len(pool.idle) == 2  # the third disconnected
    pool.pid = -1  # as seen from a forked child: its parent's clients are not taken
    assert pool.take() is None and pool.idle == []
    w = PhysicsWorld()
    assert w.client is not None
    w.close()
    for c in pool.idle:
        w.p.disconnect(physicsClientId=c)
    pool.idle.clear()
