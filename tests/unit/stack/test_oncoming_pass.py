"""The bev planner's pass through the oncoming lane: which lane it is (the road's driving lane
of the other direction, never a shoulder or sidewalk), how far it counts as a change, and the
clear-gap rule checked by hand on CARLA's Slalom road (Town01 road 24: 4 m lanes, 11.176 m/s)."""

from pathlib import Path

import pytest

from addt_dsl.plan import RoadPlan, SegmentPlan
from addt_dsl.road import parse_xodr
from addt_dsl.road.roadspec import build_network
from addt_dsl.runtime.fastroad import FastRoad
from addt_dsl.stack.nodes import EgoBody, LatticePlanner, _across_lane, _lane_steps

TOWN01 = Path(__file__).resolve().parents[2] / "data" / "carla" / "maps" / "Town01.xodr"
V_LIMIT = 11.176  # [m/s] Town01's 25 mph
HERO = EgoBody(4.5, 2.1)  # CARLA's Slalom hero (vehicle.nissan.micra's box)
CONTAINER = (2.0, 1.0)  # [m] length, width


def _two_way(width_m: float) -> FastRoad:
    plan = RoadPlan(name="r", source="inline", segments=[SegmentPlan(kind="line", length_m=500.0)],
                    right_lanes=1, left_lanes=1, lane_width_m=width_m)
    network = build_network([plan])["r"]
    return FastRoad(network.road(next(iter(network.roads))))


ROAD = _two_way(4.0)


def test_the_oncoming_lane_is_the_roads_driving_lane_of_the_other_direction():
    # Town01 road 24: sidewalk 3, shoulder 2, driving 1 | driving -1, shoulder -2, sidewalk -3.
    road = parse_xodr(TOWN01.read_text(), str(TOWN01)).road("24")
    lanes = tuple(road.driving_lane_ids(50.0))
    assert sorted(lanes) == [-1, 1]
    assert _across_lane(-1, lanes) == 1 and _across_lane(1, lanes) == -1
    assert _across_lane(-1, (-2, -1)) is None  # one-way: no oncoming lane to use
    assert _across_lane(-2, (-2, -1, 1)) is None  # only from the lane beside the centre line


def test_the_oncoming_lane_is_one_lane_over():
    """Lane ids skip 0 at the centre line: -1 -> 1 is one lane (the lane preference counted
    it as two, 5 instead of 2.5, and staying behind the blocker won)."""
    assert _lane_steps(-1, 1) == _lane_steps(1, -1) == _lane_steps(-1, -2) == 1
    assert _lane_steps(-2, 1) == 2 and _lane_steps(2, -2) == 3 and _lane_steps(-1, -1) == 0


def _clear(near_m: float | None, v_oncoming: float = -10.0):
    """The rule for the ego (standing, centre at s = 3.3 m, lane centre) behind a container
    centred in its lane at s = 29.3 m, with a car (4.6 x 1.9 m) whose near end is `near_m`
    ahead of the ego's centre in the oncoming lane's centre, coming at `v_oncoming`."""
    planner = LatticePlanner({"cruise_speed": V_LIMIT}, HERO)
    t_own, t_opp = float(ROAD.lane_center_t(-1, 3.3)), float(ROAD.lane_center_t(1, 3.3))
    objs = [(29.3, t_own, 0.0, 0.0, *CONTAINER)]
    if near_m is not None:
        objs.append((3.3 + near_m + 2.3, t_opp, v_oncoming, 0.0, 4.6, 1.9))
    return planner._oncoming_clear(-1, 1, ROAD, 3.3, t_own, 0.0, objs, 200.0, V_LIMIT)


def test_the_clear_gap_by_hand():
    """The pass ends when the ego's rear is 5 m past the container's front (30.3 m) and it has
    made 0.75 of a 33.53 m return (3 s at 11.176 m/s): its centre travels 30.3 + 5 + 2.25 +
    25.15 - 3.3 = 59.4 m, from standstill at 2 m/s^2 to 11.176 m/s: 31.23 m in 5.588 s, then
    28.17 m in 2.521 s, T = 8.109 s; its front then 61.65 m ahead of its front now plus 2.25 m
    (61.65 m from its centre now). Two clauses, over T + 2 s = 10.109 s:
    - what it cannot see may come at the speed limit: 10.109 x 11.176 = 112.98 m. The
      container (1 m wide, centred) hides the oncoming lane's centre (4 m over) beyond
      22.75 x 4 / 0.5 = 182 m (its rear 22.75 m ahead of the ego's front): 182 - 112.98 =
      69.0 >= 61.65 m, clear. A car in that lane hides what is behind it: its near end must
      be 61.65 + 112.98 = 174.63 m beyond the ego's front, 176.88 m from its centre;
    - a car it sees coming at v must stay beyond 61.65 m: its near end 61.65 + 10.109 v
      off now, 162.74 m at 10 m/s (the sight past it binds first), 203.18 m at 14 m/s."""
    assert _clear(None)[0]
    assert _clear(177.0)[0] and not _clear(176.7)[0]
    assert _clear(203.3, v_oncoming=-14.0)[0] and not _clear(203.0, v_oncoming=-14.0)[0]
    assert _clear(176.7) == (False, True, pytest.approx(28.3))  # it waits: the blocker stands


@pytest.mark.parametrize("gap_m, speed", [(6.0, 3.0), (9.0, 6.0), (12.0, 6.0)])
def test_when_the_rule_holds_the_pass_wins_over_waiting_behind(gap_m, speed):
    """The ego `gap_m` behind the container (front to rear), 0.37 m towards the centre line
    (where it looks past it), the lane seen clear: it takes the oncoming lane. With the lane
    counted as two it slowed behind the container instead (to 0-1 m/s here), came too close
    to pull out and stood there (Town01)."""
    planner = LatticePlanner({"cruise_speed": V_LIMIT}, HERO)
    t_own = float(ROAD.lane_center_t(-1, 10.0))
    objs = [(10.0 + 2.25 + gap_m + 1.0, t_own, 0.0, 0.0, *CONTAINER)]
    plan = planner.plan((10.0, t_own + 0.37, -1), speed, objs, ROAD, "r", 0.0, lambda site, v: v,
                        oncoming=(200.0, V_LIMIT, float("inf")))
    assert plan.lane == 1 and plan.speed >= speed


def _slalom_containers():
    """CARLA's Slalom containers as the waiting ego's stack tracks them (planner tuples)."""
    path = [(9.3, 2.4), (19.3, -2.6), (29.3, 1.4), (39.3, -0.6), (49.3, 1.4)]  # (s, t) from the lane centre
    boxes = [CONTAINER, CONTAINER, CONTAINER[::-1], CONTAINER[::-1], CONTAINER[::-1]]  # (along, across) the road
    return [(s, t - 2.0, 0.0, 0.0, *box) for (s, t), box in zip(path, boxes)]


def test_carlas_slalom_containers_at_the_line_hide_the_oncoming_lane():
    """CARLA's Slalom as imported, seen from where the ego stands behind the containers (its
    centre at path station 17.0 m): c1 along the centre line, across it (behind it now), c2
    on the shoulder, c3 and c5 across the road (their 2 m length across it, as the file's
    h = 0 stands them) reaching 0.4 m over the line, c4 across the right half of the lane
    (the tracked stations and offsets of the closed-loop run; the centre line at t = 0 here;
    boxes as the stack takes them, along and across the road). The group c3-c5 takes the
    oncoming lane to pass; with a lidar seeing 200 m the rule fails only because c3 hides
    that lane (its centre past c3's edge only to 9.55 x 4.03 / 2.43 = 15.8 m): with nothing
    hidden it would hold."""
    planner = LatticePlanner({"cruise_speed": V_LIMIT}, HERO)
    args = (-1, 1, ROAD, 17.0, -2.03, 0.0, _slalom_containers(), 200.0, V_LIMIT, 109.0)
    assert planner._oncoming_clear(*args) == (False, True, pytest.approx(28.8))
    assert planner._oncoming_clear(*args, occlusion=False)[0]


def test_carlas_slalom_needs_the_oncoming_lane_seen_clear_to_186_m():
    """How far the waiting ego must see the oncoming lane clear, nothing hidden (by hand, the
    stations of `test_carlas_slalom_containers_at_the_line_hide_the_oncoming_lane`): the group
    is c3-c5 (c2 stands on the shoulder, 2.6 m from the lane centre), from c3's rear (28.8 m)
    to c5's front (49.8 m); the pass ends when the ego's rear is 5 m past it and it has made
    0.75 of a 33.53 m return: its centre travels 49.8 + 5 + 2.25 + 25.15 - 17.0 = 65.2 m, from
    standstill at 2 m/s^2 to 11.176 m/s (31.23 m in 5.588 s), then 33.97 m in 3.040 s:
    T = 8.628 s, its front 67.45 m ahead of its centre now. An unseen car at 11.176 m/s comes
    11.176 x (8.628 + 2) = 118.78 m: the sight must be 67.45 + 118.78 = 186.2 m (163.9 m
    without the 2 s margin: 67.45 + 11.176 x 8.628). What its lidar can be sure of is far
    less: the default lidar returns two rays from a car head-on to 57 m and nothing beyond its
    80 m range; CARLA's leaderboard lidar (85 m) as much. Road 24 is 109 m from junction to
    junction: beyond it a car may come in from the roads that meet there."""
    planner = LatticePlanner({"cruise_speed": V_LIMIT}, HERO)

    def clear(sight_m: float) -> bool:
        return planner._oncoming_clear(-1, 1, ROAD, 17.0, -2.03, 0.0, _slalom_containers(), sight_m, V_LIMIT,
                                       109.0, occlusion=False)[0]

    assert clear(186.3) and not clear(186.1)
    planner.PASS_MARGIN_S = 0.0
    assert clear(164.0) and not clear(163.8)
