"""The agents' step kernel (`runtime.fleet.step`) against the per-agent loop's definitions:
each run's agents in declaration order, each finding its leader with
`neighbours.leader_scan` over the members as it sees them (earlier agents moved, later
ones not, then the ego), its behaviour's acceleration by its `accel` (IDM, a cruise, a
brake: each behaviour's array law) and the move by `behaviors.advance`, bit for bit; the
compiled kernel against its Python source; a step worked by hand."""

from __future__ import annotations

import contextlib
import math
from types import SimpleNamespace

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from addt_dsl.kernel import bits, interpreted
from addt_dsl.runtime import behaviors, fleet
from addt_dsl.runtime.behaviors import LAW_NONE, Brake, Cruise, Idm, advance, idm_accel, idm_free
from addt_dsl.runtime.neighbours import LANE_WINDOW_M, leader_scan
from tests.unit.runtime.test_neighbours import Member

ROADS = ("r", "q")
SETTINGS = ({"speed": 25.0, "time_gap": 1.5, "min_gap": 2.0, "accel": 1.5, "decel": 2.0},
            {"speed": 12.0, "time_gap": 0.7, "min_gap": 0.5, "accel": 3.0, "decel": 5.5})
# The behaviours an agent may have (`which` indexes them; None: no longitudinal behaviour):
# IDM (0, 1), cruises (rate limits within a vehicle's bound; integer settings, as a source
# may give them), brakes.
BEHAVIOURS = (Idm(SETTINGS[0]), Idm(SETTINGS[1]), Cruise({"speed": 13.0}),
              Cruise({"speed": 30, "accel": 4.0, "decel": 2.5, "max_decel": 1.0}), Cruise({"speed": 0.0}),
              Brake({"decel": 8.0}), Brake({"decel": 3, "to_speed": 5.0}))


def law(which, dt):
    """The kernel's (law, settings) of behaviour `which` (None: none)."""
    if which is None:
        return LAW_NONE, ()
    return BEHAVIOURS[which].array_law(SimpleNamespace(dt=dt), 0.0)


def call(runs, width: int, python=False, placed=()):
    """`fleet.step` over `runs`: each (agents, ego, dt), an agent (road, s, t, v, length,
    scale, t_new, settings index or None), the ego (road, s, t, v, length); run r's agents
    in slots r * width.. of a padded block, those of `placed` (run, agent) teleported;
    `python`: the kernel's Python (callees too). (the block's S..ACCEL rows per run, done)."""
    n_runs = len(runs)
    flat = np.zeros((5, n_runs * width))
    flat[4] = 1.0
    teleported = np.zeros(n_runs * width, dtype=bool)
    cells, lo, t_new, laws, road, length = [], [0], [], [], [], []
    for r, (agents, _, dt) in enumerate(runs):
        for i, (rd, s, t, v, ln, scale, tn, which) in enumerate(agents):
            c = r * width + i
            flat[:, c] = (s, t, v, 0.0, scale)
            teleported[c] = (r, i) in placed
            cells.append(c), t_new.append(tn), laws.append(law(which, dt)), road.append(rd), length.append(ln)
        lo.append(lo[-1] + len(agents))
    code, params = fleet.law_params(laws)
    ego = np.array([x for _, e, _ in runs for x in e[1:4]], dtype=float)
    done = np.empty(n_runs, dtype=bool)
    with np.errstate(all="ignore"), interpreted() if python else contextlib.nullcontext():
        left = fleet.step(np.array(lo, dtype=np.int64), np.array(cells, dtype=np.int64), flat, teleported,
                      np.array(t_new, dtype=float), code, params, np.array(road, dtype=np.int64),
                      np.array(length, dtype=float), ego, np.array([e[0] for _, e, _ in runs], dtype=np.int64),
                      np.array([e[4] for _, e, _ in runs], dtype=float),
                      np.array([dt for _, _, dt in runs], dtype=float), LANE_WINDOW_M, done)
    assert left == (~done).sum()
    return [flat[:4, r * width:r * width + len(agents)] for r, (agents, _, _) in enumerate(runs)], done


def loop(agents, ego, dt):
    """The per-agent loop over one run: (s, t, v, accel) per agent after the step."""
    members = [Member(f"a{i}", ROADS[a[0]], a[1], a[2], a[3], a[4]) for i, a in enumerate(agents)]
    members.append(Member("ego", ROADS[ego[0]], ego[1], ego[2], ego[3], ego[4]))
    out = []
    for i, (_, _, _, _, _, scale, t_new, which) in enumerate(agents):
        me = members[i]
        accel = 0.0
        if which is not None:
            world = SimpleNamespace(leader_of=lambda agent: leader_scan(members, agent), dt=dt)
            accel = BEHAVIOURS[which].accel(me, world, 0.0)
        agent = SimpleNamespace(accel=0.0, speed=me.speed, heading_rel=0.0, lc_duration_s=0.0, t_target=t_new,
                                placed=False, lc_keeps_station=False, s=me.s, t=me.t, ground_scale=scale,
                                lc_centre=None)
        advance(agent, accel, 0.0, dt)
        me.s, me.t, me.speed = agent.s, agent.t, agent.speed  # later agents see it moved
        out.append((agent.s, agent.t, agent.speed, agent.accel))
    return np.array(out, dtype=float).reshape(-1, 4).T


# Stations on a coarse grid (equal stations and gaps: ties), offsets at lane centres and at
# the 1.8 m window's edges, two roads, a few lengths (equal gaps need equal ones), lane
# changes (a new offset), agents under each behaviour or none, bends (ground scale).
stations = st.one_of(st.integers(0, 12).map(lambda i: 5.0 * i), st.floats(-10.0, 80.0))
offsets = st.one_of(st.sampled_from([-5.25, -1.75, 1.75, 0.05, -1.75 + 1.8, -1.75 - 1.8]), st.floats(-7.0, 3.5))
speeds = st.one_of(st.floats(0.0, 40.0), st.sampled_from([0.0, -0.0, 20.0]))
agent = st.tuples(st.sampled_from([0, 0, 1]), stations, offsets, speeds, st.sampled_from([4.6, 4.6, 12.0, 0.6]),
                  st.sampled_from([1.0, 1.0, 0.97, 1.04]), st.none() | st.sampled_from([0.3, -3.5]) | offsets,
                  st.sampled_from([0, 1, 0, None, 2, 3, 4, 5, 6]))
ego_ = st.tuples(st.sampled_from([0, 1]), stations, offsets, speeds, st.sampled_from([4.6, 5.0]))


def with_offsets(agents):
    """t_new None: the agent keeps its offset; a number: its offset moves by it (a lane change)."""
    return [(*a[:6], a[2] if a[6] is None else a[2] + a[6], a[7]) for a in agents]


@settings(max_examples=150, deadline=None)
@given(st.lists(st.tuples(st.lists(agent, min_size=1, max_size=10), ego_, st.sampled_from([0.05, 0.1])),
                min_size=1, max_size=4), st.integers(2, 4))
def test_each_run_steps_as_the_per_agent_loop(runs, steps):
    """Several steps of a batch (each starting where the last ended): every agent's station,
    offset, speed and acceleration are the loop's, bit for bit, whatever the other runs."""
    runs = [(with_offsets(agents), ego, dt) for agents, ego, dt in runs]
    width = max(len(a) for a, _, _ in runs) + 1
    for _ in range(steps):
        got, done = call(runs, width)
        assert done.all()
        nxt = []
        for (agents, ego, dt), g in zip(runs, got):
            want = loop(agents, ego, dt)
            assert g.tobytes() == want.tobytes()
            agents = [(a[0], s, t, v, *a[4:]) for a, (s, t, v) in zip(agents, g[:3].T.tolist())]
            nxt.append((agents, (ego[0], ego[1] + 0.4, *ego[2:]), dt))
        runs = nxt


weird = st.sampled_from([math.nan, math.inf, -math.inf, -0.0, 0.0, 1e-300])


@settings(max_examples=150, deadline=None)
@given(st.lists(st.tuples(st.lists(agent, min_size=0, max_size=8), ego_, st.sampled_from([0.05, 0.1])),
                min_size=1, max_size=5), st.data())
def test_compiled_gives_its_python_bits(runs, data):
    """The compiled kernel against its Python (`kernel.interpreted`) over padded batches of 0..8 agents a run,
    with non-finite or signed-zero stations, offsets, speeds and ground scales, teleported
    agents (a run with one, or with a non-finite station or offset, its ego's too, is left
    untouched, `done` False)."""
    def odd(x):
        return data.draw(weird) if data.draw(st.integers(0, 9)) == 0 else x

    runs = [([(a[0], odd(a[1]), odd(a[2]), odd(a[3]), a[4], odd(a[5]), *a[6:]) for a in with_offsets(agents)],
             (ego[0], odd(ego[1]), odd(ego[2]), odd(ego[3]), ego[4]), dt) for agents, ego, dt in runs]
    placed = {(r, i) for r, (agents, _, _) in enumerate(runs) for i in range(len(agents))
              if data.draw(st.integers(0, 19)) == 0}
    width = max(len(a) for a, _, _ in runs) + 2
    got, done = call(runs, width, placed=placed)
    want, done_py = call(runs, width, True, placed)
    assert done.tolist() == done_py.tolist()
    assert all(bits(g) == bits(w) for g, w in zip(got, want))
    for r, ((agents, ego, _), g, ok) in enumerate(zip(runs, got, done.tolist())):
        finite = all(math.isfinite(a[1]) and math.isfinite(a[2]) for a in agents)
        assert ok == (finite and math.isfinite(ego[1]) and math.isfinite(ego[2])
                      and not any((r, i) in placed for i in range(len(agents))))
        if not ok:
            assert g.tobytes() == np.array([[a[1] for a in agents], [a[2] for a in agents], [a[3] for a in agents],
                                            [0.0] * len(agents)]).reshape(4, -1).tobytes()


def test_idm_powers_are_libm_pow():
    """IDM's (s* / gap) ** 2 compiled is libm's pow (Python's `**`), not x * x: they differ
    in the last bit for ~0.1% of x, and the kernel must keep the loop's bits."""
    rng = np.random.default_rng(7)
    n = 40000
    v, gap, lead = (rng.uniform(lo, hi, n).tolist() for lo, hi in ((0.0, 40.0), (0.2, 80.0), (0.0, 40.0)))
    p = list(law(0, 0.1)[1])
    compiled = idm_accel.dispatcher()
    differ = 0
    for vi, gi, li in zip(v, gap, lead):
        free = idm_free(vi, p[0])
        assert free == 1.0 - pow(vi / p[0], 4)
        want = idm_accel.py_func(vi, free, gi, li, *p[1:])
        assert compiled(vi, free, gi, li, *p[1:]) == want
        x = (p[3] + max(0.0, vi * p[2] + vi * (vi - li) / p[4])) / gi
        differ += want != p[1] * (free - x * x)
    assert differ > 0  # (the inputs reach cases where x * x would differ)


def test_a_step_by_hand():
    """Two IDM cars in one lane (settings 0: v0 25 m/s, a 1.5, b 2, T 1.5 s, s0 2 m), the
    leader 30 m ahead at 10 m/s, the follower at 20 m/s, dt 0.1 s; the ego far behind on
    another lane. Declared leader first, the follower sees it moved; follower first, where
    it was."""
    v0, a, b, T, s0, dt = 25.0, 1.5, 2.0, 1.5, 2.0, 0.1
    lead_acc = a * (1.0 - (10.0 / v0) ** 4)  # no one ahead
    lead_v = 10.0 + lead_acc * dt
    lead_s = 50.0 + lead_v * dt

    def follower(leader_s, leader_v):
        gap = leader_s - 20.0 - 0.5 * (4.6 + 4.6)
        s_star = s0 + max(0.0, 20.0 * T + 20.0 * (20.0 - leader_v) / (2.0 * math.sqrt(a * b)))
        acc = a * (1.0 - (20.0 / v0) ** 4 - (s_star / gap) ** 2)
        return acc, 20.0 + acc * dt

    ego = (0, -100.0, -5.25, 20.0, 4.6)
    lead, follow = (0, 50.0, -1.75, 10.0, 4.6, 1.0, -1.75, 0), (0, 20.0, -1.75, 20.0, 4.6, 1.0, -1.75, 0)
    (first,), _ = call([([lead, follow], ego, dt)], 2)
    acc, v = follower(lead_s, lead_v)
    assert first[:, 0].tolist() == [lead_s, -1.75, lead_v, lead_acc]
    assert first[:, 1].tolist() == [20.0 + v * dt, -1.75, v, acc]
    (second,), _ = call([([follow, lead], ego, dt)], 2)
    acc, v = follower(50.0, 10.0)
    assert second[:, 0].tolist() == [20.0 + v * dt, -1.75, v, acc]
    assert second[:, 1].tolist() == first[:, 0].tolist()
    assert second[3, 0] != first[3, 1]  # (the order of declaration matters)
    # a lane change: the ground step splits into along and across
    (third,), _ = call([([(0, 50.0, -1.75, 10.0, 4.6, 0.5, -1.45, None)], ego, dt)], 1)
    along, across = 10.0 * dt, -1.45 - -1.75
    assert third[:, 0].tolist() == [50.0 + math.sqrt(along * along - across * across) / 0.5, -1.45, 10.0, 0.0]


def test_idm_is_the_behaviours_one_definition():
    assert fleet.idm_free is behaviors.idm_free and fleet.idm_accel is behaviors.idm_accel


def test_equal_gaps_go_to_the_first_declared():
    """Two cars at the same station ahead of a follower, the first declared having just moved
    there (it lands after the other in the sorted list): the follower's leader is the first
    declared (its speed, 5 m/s, not the other's 0), as the loop's scan has it; the ego at the
    same station too, last in member order."""
    dt = 0.1
    mover, stander = (0, 49.5, -1.75, 5.0, 4.6, 1.0, -1.75, None), (0, 50.0, -1.75, 0.0, 4.6, 1.0, -1.75, None)
    follower = (0, 20.0, -1.75, 20.0, 4.6, 1.0, -1.75, 0)
    ego = (0, 50.0, -1.75, 30.0, 4.6)
    agents = [mover, stander, follower]
    (got,), _ = call([(agents, ego, dt)], 3)
    assert got[0, :2].tolist() == [50.0, 50.0]  # (both at 50 m when the follower looks)
    assert got.tobytes() == loop(agents, ego, dt).tobytes()
    behind_mover = Idm(SETTINGS[0]).accel(SimpleNamespace(speed=20.0), SimpleNamespace(leader_of=lambda a: (25.4, 5.0)),
                                          0.0)
    assert got[3, 2] == behind_mover
    assert got[3, 2] != Idm(SETTINGS[0]).accel(SimpleNamespace(speed=20.0),
                                               SimpleNamespace(leader_of=lambda a: (25.4, 0.0)), 0.0)


def test_speed_laws_are_pythons_min_and_max_compiled_and_interpreted():
    """`speed_tracking` and `brake_accel`, compiled and as Python, give the bits of the
    expressions they were written from (Python's `min` and `max`: on a NaN or an equal the
    first stays), over signed zeros, infinities, NaNs and integer settings."""
    values = [0.0, -0.0, 1.0, -1.0, 3, 2.5, 1e-300, math.inf, -math.inf, math.nan, 7.25, 20.0]
    track, brake = behaviors.speed_tracking, behaviors.brake_accel
    compiled_track, compiled_brake = track.dispatcher(), brake.dispatcher()
    for v in values:
        for target in values:
            for limit in (3, 2.5, 0.0, -0.0, math.inf, math.nan):
                for dt in (0.01, 0.1):
                    x = (target - v) / dt
                    want = bits(max(-limit, min(2.5, x)))
                    assert bits(track.py_func(v, target, 2.5, limit, dt)) == want
                    assert bits(compiled_track(v, target, 2.5, limit, dt)) == want
                    want = bits(max(-2.5, min(limit, x)))
                    assert bits(track.py_func(v, target, limit, 2.5, dt)) == want
                    assert bits(compiled_track(v, target, limit, 2.5, dt)) == want
                    want = bits(min(0.0, max(-limit, x)))
                    assert bits(brake.py_func(v, limit, target, dt)) == want
                    assert bits(compiled_brake(v, limit, target, dt)) == want
