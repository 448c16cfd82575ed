"""The dense-traffic lookups against brute force: `LeaderIndex` (sorted per-road stations)
against every-actor scans, and the clearance broad phase against visiting every pair,
on random configurations with ties, lane-window edges and agents moving one by one."""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from addt_dsl.runtime import collision as C
from addt_dsl.runtime.neighbours import LeaderIndex, leader_scan
from tests.unit.runtime.test_collision_kernel import max_separation


@dataclass
class Member:
    name: str
    road: str
    s: float
    t: float
    speed: float
    length_m: float


def bits(result):
    """A lookup's answer with its floats as bit patterns (-0.0 differs from 0.0)."""
    return None if result is None else tuple(struct.pack("<d", v) for v in result)


def old_leader_of(members, agent):
    """`_Run.leader_of` before the index (occupants: agents, then the ego), verbatim."""
    def occupants(road_id):
        for m in members:
            if m.road == road_id:
                yield m.name, m.s, m.t, m.speed, m.length_m

    best = None
    for other_name, s, t, speed, length in occupants(agent.road):
        if other_name == agent.name or abs(t - agent.t) > 1.8:
            continue
        gap = s - agent.s - 0.5 * (length + agent.length_m)
        if s > agent.s and (best is None or gap < best[0]):
            best = (gap, speed)
    return best


# Stations on a coarse grid (many equal stations: gap ties), or anywhere; offsets near
# lane centres and just inside/outside the 1.8 m window; a few lengths (ties need equal ones).
stations = st.one_of(st.integers(0, 12).map(lambda i: 5.0 * i), st.floats(-10.0, 80.0))
offsets = st.one_of(st.sampled_from([-5.25, -1.75, 1.75, -3.55, 0.05, -1.75 + 1.8, -1.75 - 1.8]),
                    st.floats(-7.0, 3.5))
member = st.tuples(st.sampled_from(["r", "r", "r", "q"]), stations, offsets,
                   st.floats(0.0, 40.0), st.sampled_from([4.6, 4.6, 4.6, 12.0, 0.6]))


def make_members(rows):
    return [Member(f"a{i}" if i < len(rows) - 1 else "ego", *row) for i, row in enumerate(rows)]


@settings(max_examples=300, deadline=None)
@given(st.lists(member, min_size=1, max_size=30))
def test_index_answers_like_the_scan_and_the_old_lookup(rows):
    members = make_members(rows)
    index = LeaderIndex(members)
    for m in members:
        expected = bits(old_leader_of(members, m))
        assert bits(leader_scan(members, m)) == expected
        assert bits(index.leader(m)) == expected


@settings(max_examples=200, deadline=None)
@given(st.lists(member, min_size=2, max_size=25), st.data())
def test_index_follows_members_moving_one_by_one(rows, data):
    """As in the loop: each agent in turn queries its leader, then moves (stations may
    pass each other or land on another's exactly); later agents see it moved."""
    members = make_members(rows)
    index = LeaderIndex(members)
    for _ in range(3):
        for i, m in enumerate(members):
            assert bits(index.leader(m)) == bits(old_leader_of(members, m))
            m.s = data.draw(st.one_of(st.just(m.s), st.sampled_from([o.s for o in members]),
                                      st.floats(m.s, m.s + 30.0)))
            m.t = data.draw(st.one_of(st.just(m.t), offsets))
            index.moved(i)


def test_equal_gaps_go_to_the_first_member_whatever_the_station_order():
    # Two leaders at the same gap (the nearer one shorter); the later-declared one sorts first.
    agent = Member("a0", "r", 0.0, -1.75, 10.0, 4.0)
    far = Member("a1", "r", 14.0, -1.75, 7.0, 12.0)  # gap 14 - 8 = 6
    near = Member("a2", "r", 10.0, -1.75, 9.0, 4.0)  # gap 10 - 4 = 6
    members = [agent, far, near]
    assert old_leader_of(members, agent) == (6.0, far.speed)
    assert LeaderIndex(members).leader(agent) == (6.0, far.speed)
    members[1:] = [near, far]  # declared the other way round: the nearer one
    assert LeaderIndex(members).leader(agent) == (6.0, near.speed) == old_leader_of(members, agent)


def test_a_non_finite_station_falls_back_to_the_scan():
    members = make_members([("r", 0.0, -1.75, 10.0, 4.6), ("r", 20.0, -1.75, 5.0, 4.6),
                            ("r", 30.0, -1.75, 6.0, 4.6)])
    index = LeaderIndex(members)
    members[1].s = math.nan
    index.moved(1)
    assert bits(index.leader(members[0])) == bits(old_leader_of(members, members[0]))
    assert index.leader(members[0])[1] == 6.0


# ---------------------------------------------------------------- clearances

def old_box_separation(a, b):
    """`world.box_separation` before it was a kernel (its formula with the plain `max`:
    `test_collision_kernel.max_separation`)."""
    xa, ya, ha, la, wa = a
    xb, yb, hb, lb, wb = b
    return max_separation(xb - xa, yb - ya, math.cos(ha), math.sin(ha), math.cos(hb), math.sin(hb), la, wa, lb, wb)


def all_pairs(names, boxes):
    """The clearance loop before the broad phase: every pair, in order (verbatim)."""
    reach = {n: 0.5 * math.hypot(boxes[n][3], boxes[n][4]) for n in names}
    clear = {n: math.inf for n in names}
    touching = []
    for i, a in enumerate(names):
        ax, ay = boxes[a][0], boxes[a][1]
        for b in names[i + 1:]:
            dist = math.hypot(ax - boxes[b][0], ay - boxes[b][1])
            r = reach[a] + reach[b]
            sep = dist - r if dist > r + 5.0 else old_box_separation(boxes[a], boxes[b])
            if sep < clear[a]:
                clear[a] = sep
            if sep < clear[b]:
                clear[b] = sep
            if sep <= 0.0:
                touching.append((a, b))
    return {n: clear[n] if math.isfinite(clear[n]) else 1e3 for n in names}, touching


def step_rows(names, boxes):
    """A step's rows as `phases.Record` keeps them (x, y, heading first, the clearance
    last) and the actors' (length, width)."""
    rows = np.zeros((len(names), 11))
    rows[:, :3] = [boxes[n][:3] for n in names]
    rows[:, -1] = np.nan  # (written by the clearances)
    return rows, np.array([boxes[n][3:] for n in names], dtype=float).reshape(-1, 2)


box = st.tuples(st.one_of(st.integers(0, 20).map(lambda i: 6.0 * i), st.floats(-50.0, 200.0)),
                st.sampled_from([-5.25, -1.75, 1.75]) | st.floats(-8.0, 4.0),
                st.floats(-0.4, 0.4) | st.just(0.0), st.sampled_from([(4.6, 1.9), (12.0, 2.5), (0.6, 0.6)]))


@settings(max_examples=300, deadline=None)
@given(st.lists(box, min_size=1, max_size=40))
def test_broad_phase_clearances_equal_all_pairs(rows):
    names = ["ego"] + [f"a{i}" for i in range(len(rows) - 1)]
    poses = {n: (x, y, h) for n, (x, y, h, _) in zip(names, rows)}
    sizes = {n: size for n, (_, _, _, size) in zip(names, rows)}
    boxes = {n: (*poses[n], *sizes[n]) for n in names}
    run = SimpleNamespace(contacts=set(), events=[])
    rows, footprints = step_rows(names, boxes)
    collided = C.clearances(rows, names, footprints, run, 0.0)
    clear, touching = all_pairs(names, boxes)
    for i, n in enumerate(names):
        assert struct.pack("<d", rows[i, -1]) == struct.pack("<d", clear[n])
    assert [tuple(e.detail["actors"]) for e in run.events] == touching
    assert collided == any("ego" in pair for pair in touching)


@settings(max_examples=100, deadline=None)
@given(st.lists(st.lists(box, min_size=1, max_size=40), min_size=1, max_size=4))
def test_batch_clearances_equal_each_run_alone(runs):
    """Runs' clearances in one broad phase (`clearances_batch`) are each run's all pairs."""
    items, expected = [], []
    for rows in runs:
        names = ["ego"] + [f"a{i}" for i in range(len(rows) - 1)]
        boxes = {n: (x, y, h, *size) for n, (x, y, h, size) in zip(names, rows)}
        run = SimpleNamespace(contacts=set(), events=[])
        rows, footprints = step_rows(names, boxes)
        items.append((rows, names, footprints, run, 0.0))
        expected.append(all_pairs(names, boxes))
    collided = C.clearances_batch(items)
    for item, (clear, touching), hit in zip(items, expected, collided):
        rows, names, run = item[0], item[1], item[3]
        assert [struct.pack("<d", rows[i, -1]) for i in range(len(names))] == \
            [struct.pack("<d", clear[n]) for n in names]
        assert [tuple(e.detail["actors"]) for e in run.events] == touching
        assert hit == any("ego" in pair for pair in touching)


# ---------------------------------------------------------------- the lookups that became nearest_ahead

class _Straight:
    """A road along +x: station = x, offset = y, heading 0 (what `_leader_by_position` asks)."""

    def point(self, s, t):
        return s, t, 0.0

    def project(self, x, y, hint):
        return x, y

    def reference_pose(self, u):
        return u, 0.0, 0.0


def old_leader_by_position(run, agent, reach_m=150.0):
    """`_Run._leader_by_position` before it was `leader_scan` over projected actors (verbatim)."""
    road = run.agent_roads[agent.name].road
    ax, ay, _ = run.world_pose.get(agent.name, road.point(agent.s, agent.t))
    best = None
    for name, (x, y, heading) in run.world_pose.items():
        if name == agent.name or abs(x - ax) > reach_m or abs(y - ay) > reach_m:
            continue
        dist = math.hypot(x - ax, y - ay)
        if dist > reach_m:
            continue
        u, t = road.project(x, y, agent.s + dist)
        if u <= agent.s or abs(t - agent.t) > 1.8:
            continue
        speed, length = (run.ego.speed, run.ego_plan.length_m) if name == "ego" else (
            run.agent_by_name[name].speed, run.agent_by_name[name].length_m)
        gap = u - agent.s - 0.5 * (length + agent.length_m)
        if best is None or gap < best[0]:
            along = speed * math.cos(heading - road.reference_pose(u)[2])
            best = (gap, along)
    return best


def fake_run(members, headings):
    """A run state with `members` (the last is the ego) posed on one straight road."""
    *agents, ego = members
    road = SimpleNamespace(road=_Straight())
    return SimpleNamespace(
        agent_roads={m.name: road for m in agents}, agent_by_name={m.name: m for m in agents},
        world_pose={m.name: (m.s, m.t, h) for m, h in zip(members, headings)},
        ego=SimpleNamespace(speed=ego.speed), ego_plan=SimpleNamespace(length_m=ego.length_m))


@settings(max_examples=200, deadline=None)
@given(st.lists(member.map(lambda row: ("r", *row[1:])), min_size=2, max_size=20),
       st.lists(st.floats(-3.0, 3.0), min_size=20, max_size=20))
def test_leader_by_position_is_the_old_lookup(rows, headings):
    from addt_dsl.runtime.state import RunState

    members = make_members(rows)
    run = fake_run(members, headings)
    for m in members[:-1]:
        assert bits(RunState._leader_by_position(run, m)) == bits(old_leader_by_position(run, m))


def old_nearest_ahead(agent, occupants) -> str:
    """`behaviors._nearest_ahead` before it was `nearest_ahead` (verbatim): the least
    station ahead within `< 1.8` m."""
    best, best_s = "", math.inf
    for name, s, t, _, _ in occupants:
        if name != agent.name and s > agent.s and abs(t - agent.t) < 1.8 and s < best_s:
            best, best_s = name, s
    return best


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(st.just("r"), st.integers(0, 12).map(lambda i: 5.0 * i), offsets, st.floats(0.0, 40.0),
                          st.just(4.6)), min_size=1, max_size=20))
def test_the_overtake_target_is_the_old_one_among_equal_lengths(rows):
    """With equal lengths and stations on a grid (gaps exact), least gap is least station;
    off the window's edge the two agree (exactly 1.8 m apart: now in the lane, as `idm`
    has always counted it). Elsewhere the target is now the least bumper gap, a longer
    vehicle ahead counted by its rear, and gaps that round equal go to the first declared."""
    from addt_dsl.runtime.behaviors import _nearest_ahead

    members = make_members(rows)
    world = SimpleNamespace(occupants=lambda road: iter(members))
    for m in members:
        old = [(o.name, o.s, o.t, o.speed, o.length_m) for o in members]
        if any(abs(abs(o.t - m.t) - 1.8) < 1e-12 for o in members if o is not m):
            continue  # the window's edge: `<` before, `<=` (the lane window) now
        assert _nearest_ahead(m, world) == old_nearest_ahead(m, old)
