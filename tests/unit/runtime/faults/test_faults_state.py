"""bitflip on state sites: the planner's manoeuvre state and committed manoeuvre and the
tracker's tracks are memory a flip stays in until the node's own logic overwrites it."""

import copy

import pytest
from hypothesis import given
from hypothesis import strategies as st
from tests.unit.runtime.faults.faultkit import bound, schedule
from tests.unit.stack.test_planner import ROAD2, _plan

from addt_dsl.compiler import compile_source
from addt_dsl.registry import FAULTS
from addt_dsl.runtime.faults import flip_float64_bit
from addt_dsl.runtime.faults.base import flip_int64_bit, flip_stored_bit
from addt_dsl.stack.bev import BevStack
from addt_dsl.stack.nodes import LatticePlanner, Obj, Tracker

NODES = {"tracker": ("tracker.vx", "tracker.tracks"),
         "planner": ("planner.speed", "planner.state", "planner.trajectory")}


def _no_fault(site, value):
    return value


@given(st.integers(-(2 ** 63), 2 ** 63 - 1), st.integers(0, 63))
def test_int64_flip_is_an_involution_within_int64(x, bit):
    y = flip_int64_bit(x, bit)
    assert -(2 ** 63) <= y < 2 ** 63 and y != x
    assert flip_int64_bit(y, bit) == x
    assert ((x ^ y) & (2 ** 64 - 1)) == 1 << bit


def test_stored_integers_flip_as_int64_and_floats_as_float64():
    assert flip_stored_bit(-1, 1) == -3  # ...11111111 -> ...11111101
    assert flip_stored_bit(-1, 63) == 2 ** 63 - 1
    assert flip_stored_bit(2.5, 62) == flip_float64_bit(2.5, 62)
    assert isinstance(flip_stored_bit(3, 0), int) and flip_stored_bit(3, 0) == 2


def _tracker_with_lead(x0=50.0, v=20.0):
    tr = Tracker()
    for k in range(5):
        t = 0.1 * k
        tr.update([Obj(x0 + v * t, 0.0, 0.0, v, 0.0, 4.6, 1.9)], t, _no_fault)
    return tr


def test_a_track_flip_changes_the_stored_track_at_its_instant():
    sched, kind, events = bound("bitflip", target="tracker.tracks", nodes=NODES, bit=62, start=0.55, end=0.55)
    tr = _tracker_with_lead()
    before = list(tr.tracks)
    sched.upset(tr, 0.5)  # before the instant: nothing
    assert tr.tracks == before and not events
    sched.upset(tr, 0.6)
    (e,) = events
    assert e.time_s == 0.6 and e.detail["location"].startswith("tracker.tracks:0.")
    field = e.detail["location"].rsplit(".", 1)[1]
    i = Tracker.TRACK_FIELDS.index(field)
    stored = [*vars(tr.tracks[0][0]).values()][:7] + [tr.tracks[0][1], *tr.tracks[0][2]]
    old = [*vars(before[0][0]).values()][:7] + [before[0][1], *before[0][2]]
    assert stored[i] == flip_float64_bit(old[i], 62) == e.detail["value"]
    assert [a for j, a in enumerate(stored) if j != i] == [a for j, a in enumerate(old) if j != i]
    sched.upset(tr, 0.7)  # one flip, applied once
    assert len(events) == 1


def test_a_flipped_track_stamp_keeps_a_ghost_alive_past_the_coasting_limit():
    # The stamp of a stationary object's track flipped upward: the tracker's own age check
    # (stamp - ts <= max_age) no longer retires it, so the ghost persists while the object
    # is long gone; the same object unflipped is retired after max_age.
    flipped, clean = Tracker(), Tracker()
    for tr in (flipped, clean):
        for k in range(5):
            tr.update([Obj(30.0, 0.0, 0.0, 0.0, 0.0, 4.6, 1.9)], 0.1 * k, _no_fault)
    # Find the seed's element: redraw until the flip lands on the stamp, deterministically.
    seed = next(s for s in range(200) if _lands_on(s, "stamp"))
    sched, kind, events = bound("bitflip", target="tracker.tracks", nodes=NODES, bit=62, start=0.45, end=0.45,
                                seed=seed)
    sched.upset(flipped, 0.5)
    assert events[0].detail["location"] == "tracker.tracks:0.stamp"
    assert flipped.tracks[0][1] > 1e300  # 0.4 s with bit 62 set: exponent 0x3FD -> 0x7FD
    for k in range(6, 40):  # the object left the sensor's view: empty frames for 3.4 s
        for tr in (flipped, clean):
            sched.upset(tr, 0.1 * k)
            tr.update([], 0.1 * k, _no_fault)
    assert clean.tracks == [] and clean.objects_at(4.0) == []
    assert len(flipped.tracks) == 1 and len(flipped.objects_at(4.0)) == 1  # persisted: still reported


def _lands_on(seed, field):
    sched, _, events = bound("bitflip", target="tracker.tracks", nodes=NODES, bit=62, start=0.0, end=0.0,
                             seed=seed)
    tr = Tracker()
    tr.update([Obj(30.0, 0.0, 0.0, 0.0, 0.0, 4.6, 1.9)], 0.0, _no_fault)
    sched.upset(tr, 0.0)
    return events[0].detail["location"].endswith("." + field)


def test_a_flip_waits_for_state_to_hold_something():
    sched, kind, events = bound("bitflip", target="tracker.tracks", nodes=NODES, start=1.0, end=1.0)
    tr = Tracker()
    sched.upset(tr, 1.0)  # no tracks yet
    assert not events
    tr.update([Obj(10.0, 0.0, 0.0, 1.0, 0.0, 4.6, 1.9)], 1.1, _no_fault)
    sched.upset(tr, 1.2)
    assert len(events) == 1 and events[0].time_s == 1.2


def _planner_flip(field_name, bit, seed_range=range(300)):
    """A planner and a schedule whose one flip at 1 s lands on `field_name` of its site."""
    site = "planner.state" if field_name in ("current_lane", "home_lane", "last_change_s", "aeb_stage",
                                             "threat_s") else "planner.trajectory"
    for seed in seed_range:
        sched, _, events = bound("bitflip", target=site, nodes=NODES, bit=bit, start=1.0, end=1.0, seed=seed)
        planner = LatticePlanner({"cruise_speed": 25.0})
        _plan(planner, ROAD2, 100.0, -1, 25.0, [], now=0.9)
        sched.upset(planner, 1.0)
        if events and events[0].detail["location"] == f"{site}:{field_name}":
            return planner, sched, events
    raise AssertionError(f"no seed in {seed_range} lands on {field_name}")


def test_a_committed_manoeuvre_flip_persists_over_replans_while_the_target_lane_stays():
    planner, sched, events = _planner_flip("path_length", 62)
    clean = LatticePlanner({"cruise_speed": 25.0})
    _plan(clean, ROAD2, 100.0, -1, 25.0, [], now=0.9)
    (e,) = events
    assert planner.maneuver[3] == e.detail["value"] == flip_float64_bit(e.detail["before"], 62)
    for k in range(1, 40):  # 4 s of replanning at 10 Hz: the target lane stays -1
        now, s = 1.0 + 0.1 * k, 100.0 + 2.5 * k
        sched.upset(planner, now)
        p = _plan(planner, ROAD2, s, -1, 25.0, [], now=now)
        c = _plan(clean, ROAD2, s, -1, 25.0, [], now=now)
        assert p.lateral_length_m == e.detail["value"] != c.lateral_length_m  # every plan publishes it
    assert len(events) == 1


def test_a_manoeuvre_flip_is_overwritten_when_the_planner_picks_a_new_target_lane():
    planner, sched, events = _planner_flip("lane", 40)
    assert planner.maneuver[0] == events[0].detail["value"] != -1
    p = _plan(planner, ROAD2, 103.0, -1, 25.0, [], now=1.1)
    # The stored lane differs from the planned one: the planner restarts the manoeuvre here.
    assert planner.maneuver[0] == -1 and p.s_start == 103.0


def test_a_home_lane_flip_moves_the_ego_over_for_good():
    # ...11111111 (lane -1) with bit 0 flipped is lane -2, a lane that exists: with the `keep`
    # policy the planner now prefers it and stays there until the flip is overwritten (never).
    planner, sched, events = _planner_flip("home_lane", 0)
    assert planner.home_lane == -2
    lanes, lane = [], -1
    for k in range(1, 80):
        now, s = 1.0 + 0.1 * k, 100.0 + 2.5 * k
        p = _plan(planner, ROAD2, s, lane, 25.0, [], now=now)
        lanes.append(p.lane)
        lane = p.lane
    assert lanes[0] == -2 and set(lanes[-40:]) == {-2}
    clean = LatticePlanner({"cruise_speed": 25.0})
    assert {_plan(clean, ROAD2, 100.0 + k, -1, 25.0, [], now=0.1 * k).lane for k in range(20)} == {-1}


def test_state_sites_are_bitflip_targets_only_and_the_compiler_lists_them():
    sites = {"planner.state", "planner.trajectory", "tracker.tracks"}
    assert sites <= FAULTS.get("bitflip").valid_targets({}, BevStack)
    for kind in ("stuck", "random_value"):
        assert not sites & FAULTS.get(kind).valid_targets({}, BevStack)
    src = ("scenario s { duration 5 s\n road r { line length 300 m\n lanes right 1 width 3.5 m }\n"
           " ego car on r lane -1 at 10 m speed 10 m/s { stack bev\n sensor lidar }\n"
           " faults { at 1 s bitflip planner.trajectry\n at 1 s stuck planner.trajectory value 0\n"
           " at 1 s bitflip tracker.tracks } }\n")
    result = compile_source(src, "s.addt")
    errors = [d for d in result.diagnostics if d.code == "E0107"]
    assert [d.span.line for d in errors] == [6, 7], [d.message for d in result.diagnostics]
    text = " ".join(str(n) for n in errors[0].notes)
    assert "planner.trajectory" in text and "tracker.tracks" in text


def test_node_targets_draw_state_sites_too():
    stack = type("Stack", (), {})()
    stack.nodes = {"planner": ("planner.speed",)}
    stack.state_nodes = {"planner": ("planner.state", "planner.trajectory")}
    sched2, _ = _schedule_bound(stack)
    (k,) = sched2.kinds
    assert set(k._queues) == {"planner.speed", "planner.state", "planner.trajectory"}
    assert all(k._queues.values())


def _schedule_bound(stack):
    sched, events = schedule({"kind": "bitflip", "target": "planner", "count": 200})
    sched.bind(stack, lambda: 0.0)
    return sched, events


@pytest.mark.parametrize("site", ["planner.state", "planner.trajectory", "tracker.tracks"])
def test_same_seed_same_element_and_bit(site):
    node = _tracker_with_lead() if site == "tracker.tracks" else None
    if node is None:
        node = LatticePlanner({"cruise_speed": 25.0})
        _plan(node, ROAD2, 100.0, -1, 25.0, [], now=0.0)
    out = []
    for _ in range(2):
        sched, _, events = bound("bitflip", target=site, nodes=NODES, count=3, start=0.0, end=0.0, seed=7)
        n = copy.deepcopy(node)
        sched.upset(n, 0.0)
        out.append([(e.detail["location"], e.detail["bit"], repr(e.detail["value"])) for e in events])
    assert out[0] == out[1] and len(out[0]) == 3
