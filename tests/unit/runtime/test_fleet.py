"""The agents' array step (`runtime.fleet`) against the per-agent definitions: leaders
from the sorted views against `neighbours.leader_scan` over the members as each agent
sees them in the sequential step (earlier agents moved, later ones not), and the IDM
accelerations against `behaviors.Idm.accel`, bit for bit."""

from __future__ import annotations

import copy
import math
import struct
from types import SimpleNamespace

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from addt_dsl.runtime import fleet
from addt_dsl.runtime.behaviors import Idm
from addt_dsl.runtime.neighbours import leader_scan
from tests.unit.runtime.test_neighbours import Member


def bits(values):
    return None if values is None else tuple(struct.pack("<d", float(v)) for v in values)


# Stations on a coarse grid (equal stations and gaps: ties), offsets at lane centres and
# at the 1.8 m window's edges, two roads, a few lengths (equal gaps need equal ones).
stations = st.one_of(st.integers(0, 12).map(lambda i: 5.0 * i), st.floats(-10.0, 80.0))
offsets = st.one_of(st.sampled_from([-5.25, -1.75, 1.75, 0.05, -1.75 + 1.8, -1.75 - 1.8]), st.floats(-7.0, 3.5))
member = st.tuples(st.sampled_from(["r", "r", "r", "q"]), stations, offsets, st.floats(0.0, 40.0),
                   st.sampled_from([4.6, 4.6, 12.0, 0.6]))
moves = st.tuples(st.sampled_from([0.0, 0.2, 5.0]) | st.floats(0.0, 20.0), offsets, st.floats(0.0, 40.0))


@settings(max_examples=200, deadline=None)
@given(st.lists(member, min_size=2, max_size=25), st.data(), st.sampled_from([1, 2, 12]))
def test_views_answer_like_the_scan_of_what_each_agent_sees(rows, data, window):
    *agents, ego = [Member(f"a{i}", *row) for i, row in enumerate(rows)]
    ego.name = "ego"
    moved = copy.deepcopy(agents)
    for m in moved:  # where the agents are after their step (stations only grow)
        ds, m.t, m.speed = data.draw(moves)
        m.s += ds
    roads = {"r": 0, "q": 1}
    s, t, v, length = (np.array([getattr(a, f) for a in agents]) for f in ("s", "t", "speed", "length_m"))
    views = fleet.Views([(length, np.array([roads[a.road] for a in agents]), ego.length_m, roads[ego.road])])
    ego_state = (np.array([ego.s]), np.array([ego.t]), np.array([ego.speed]))
    new = tuple(np.array([getattr(a, f) for a in moved]) for f in ("s", "t", "speed"))
    fleet.WINDOW, window = window, fleet.WINDOW  # small windows: the widening is exercised
    try:
        jacobi = views.leaders(views.jacobi(s, t, v, ego_state), s, t, length)
        sequential = views.leaders(views.sequential(s, t, v, new, ego_state), s, t, length)
    finally:
        fleet.WINDOW = window
    for i, agent in enumerate(agents):
        for answer, seen in ((jacobi, [*agents, ego]), (sequential, [*moved[:i], *agents[i:], ego])):
            found, gap, speed = (a[i] for a in answer)
            assert bits((gap, speed) if found else None) == bits(leader_scan(seen, agent))


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.floats(0.0, 40.0), st.floats(0.0, 45.0), st.booleans(), st.floats(-3.0, 60.0),
                          st.floats(0.0, 40.0)), min_size=1, max_size=12))
def test_idm_accelerations_are_the_behaviours(rows):
    settings_ = [{"speed": desired, "time_gap": 1.5, "min_gap": 2.0, "accel": 1.5, "decel": 2.0} if k % 2 else
                 {"speed": desired, "time_gap": 0.7, "min_gap": 0.5, "accel": 3.0, "decel": 5.5}
                 for k, (_, desired, _, _, _) in enumerate(rows)]
    params = fleet.idm_params(settings_)
    v = np.array([r[0] for r in rows])
    found = np.array([r[2] for r in rows])
    gap, lead = np.array([r[3] for r in rows]), np.array([r[4] for r in rows])
    got = fleet.idm_accel(params, v, fleet.idm_free(params, v), found, gap, lead)
    for k, (speed, _, has, g, ls) in enumerate(rows):
        behaviour = Idm(settings_[k])
        world = SimpleNamespace(leader_of=lambda agent, answer=((g, ls) if has else None): answer)
        expected = behaviour.accel(SimpleNamespace(speed=speed), world, 0.0)
        assert struct.pack("<d", got[k]) == struct.pack("<d", expected)


@settings(max_examples=100, deadline=None)
@given(st.lists(st.lists(member, min_size=2, max_size=12), min_size=2, max_size=4), st.data(),
       st.sampled_from([1, 2, 12]))
def test_views_of_a_batch_answer_as_each_run_alone(runs, data, window):
    """Several runs' views at once (a block per run; stations, roads and keys that overlap
    across runs): each agent's answer is its run's alone, bit for bit."""
    roads = {"r": 0, "q": 1}
    members, states, alone = [], [], []
    for rows in runs:
        *agents, ego = [Member(f"a{i}", *row) for i, row in enumerate(rows)]
        s, t, v, length = (np.array([getattr(a, f) for a in agents]) for f in ("s", "t", "speed", "length_m"))
        new = tuple(np.array([getattr(a, f) + data.draw(moves)[0] * (f == "s") for a in agents])
                    for f in ("s", "t", "speed"))
        member_ = (length, np.array([roads[a.road] for a in agents]), ego.length_m, roads[ego.road])
        ego_state = (np.array([ego.s]), np.array([ego.t]), np.array([ego.speed]))
        members.append(member_)
        states.append((s, t, v, length, new, ego_state))
    fleet.WINDOW, window = window, fleet.WINDOW  # small windows: the widening is exercised
    try:
        for member_, (s, t, v, length, new, ego_state) in zip(members, states):
            one = fleet.Views([member_])
            alone.append((one.leaders(one.jacobi(s, t, v, ego_state), s, t, length),
                          one.leaders(one.sequential(s, t, v, new, ego_state), s, t, length)))
        views = fleet.Views(members)
        s, t, v, length = (np.concatenate([x[k] for x in states]) for k in range(4))
        new = tuple(np.concatenate([x[4][k] for x in states]) for k in range(3))
        ego = tuple(np.concatenate([x[5][k] for x in states]) for k in range(3))
        batch = (views.leaders(views.jacobi(s, t, v, ego), s, t, length),
                 views.leaders(views.sequential(s, t, v, new, ego), s, t, length))
    finally:
        fleet.WINDOW = window
    for which in range(2):  # (found, gap, leader speed), the speed where a leader is found
        found, gap, speed = (np.concatenate([a[which][k] for a in alone]) for k in range(3))
        got_found, got_gap, got_speed = batch[which]
        assert (got_found == found).all()
        assert got_gap.tobytes() == gap.tobytes()
        assert got_speed[found].tobytes() == speed[found].tobytes()


def nearest_ahead_by_loop(seen, i, s, t, road, length, window_m=1.8):
    """The lookup's definition, written out as a loop over every member: the nearest member
    strictly ahead of agent `i` on its road within the lane window (a finite bumper gap),
    the first in member order on equal gaps. `seen`: (member index, road, station, offset,
    speed, length) as the agent sees them, in member order. (gap, speed) or None."""
    best = None
    for m, m_road, m_s, m_t, m_v, m_len in seen:
        if m == i or m_road != road or abs(m_t - t) > window_m or not m_s > s:
            continue
        gap = m_s - s - 0.5 * (m_len + length)
        if gap < math.inf and (best is None or gap < best[0]):
            best = (gap, m_v)
    return best


# A run's step: per agent its road, where it was and where it moved (station, offset, speed);
# stations on a coarse grid (ties), moves of 0 (equal old and new stations) or small ones
# (the view's kept order stays valid from call to call), the ego's station possibly infinite.
agent_state = st.tuples(st.sampled_from([0, 0, 1]), stations, offsets, st.floats(0.0, 40.0),
                        st.sampled_from([4.6, 4.6, 12.0, 0.6]))
ego_state_ = st.tuples(st.sampled_from([0, 1]), st.one_of(stations, st.just(math.inf)), offsets,
                       st.floats(0.0, 40.0), st.sampled_from([4.6, 5.0]))
run_ = st.tuples(st.lists(agent_state, min_size=1, max_size=10), ego_state_)


@settings(max_examples=150, deadline=None)
@given(st.lists(run_, min_size=1, max_size=4), st.data(), st.sampled_from([1, 3, 12]))
def test_views_of_batches_over_steps_answer_as_the_definition(runs, data, window):
    """Several steps of a batch on the same `Views` (each view keeps and repairs its order
    from call to call): every agent's (found, gap, leader speed) in both views is the loop's
    over the members as it sees them, bit for bit; no leader: gap inf and speed 0."""
    views = fleet.Views([(np.array([a[4] for a in agents]), np.array([a[0] for a in agents]), ego[4], ego[0])
                         for agents, ego in runs])
    length = np.array([a[4] for agents, _ in runs for a in agents])
    s = np.array([a[1] for agents, _ in runs for a in agents])
    t = np.array([a[2] for agents, _ in runs for a in agents])
    v = np.array([a[3] for agents, _ in runs for a in agents])
    ego_s = np.array([ego[1] for _, ego in runs])
    fleet.WINDOW, window = window, fleet.WINDOW  # small windows: the widening is exercised
    try:
        for _ in range(3):
            ds = np.array(data.draw(st.lists(st.sampled_from([0.0, 0.0, 0.1, 2.5, 5.0]) | st.floats(0.0, 20.0),
                                             min_size=len(s), max_size=len(s))))
            new = (s + ds, t + np.array(data.draw(st.lists(st.sampled_from([0.0, 0.0, 1.75, -3.5]),
                                                             min_size=len(s), max_size=len(s)))), v[::-1].copy())
            ego = (ego_s, np.array([e[2] for _, e in runs]), np.array([e[3] for _, e in runs]))
            answers = {"jacobi": views.leaders(views.jacobi(s, t, v, ego), s, t, length),
                       "sequential": views.leaders(views.sequential(s, t, v, new, ego), s, t, length)}
            lo = 0
            for r, (agents, ego_) in enumerate(runs):
                n = len(agents)
                for i in range(lo, lo + n):
                    for kind, (found, gap, speed) in answers.items():
                        moved = range(lo, i) if kind == "sequential" else ()
                        state = lambda j: (new[0][j], new[1][j], new[2][j]) if j in moved else (s[j], t[j], v[j])  # noqa: E731
                        seen = [(j - lo, agents[j - lo][0], *state(j), length[j]) for j in range(lo, lo + n)]
                        seen.append((n, ego_[0], ego[0][r], ego[1][r], ego[2][r], ego_[4]))
                        expected = nearest_ahead_by_loop(seen, i - lo, s[i], t[i], agents[i - lo][0], length[i])
                        got = (gap[i], speed[i]) if found[i] else None
                        assert bits(got) == bits(expected), (kind, r, i)
                        if not found[i]:
                            assert gap[i] == math.inf and bits((speed[i],)) == bits((0.0,))
                lo += n
            s, t, v = new  # the next step starts where this one moved to
            ego_s = ego_s + 0.3
    finally:
        fleet.WINDOW = window
