"""Routes through road networks: `resolve_route` (road ids, turns, lane following) and
`RoutePath` (one continuous station over the legs)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from addt_dsl.runtime.fastroad import FastRoad
from addt_dsl.runtime.path import RoutePath
from addt_dsl.road import RouteError, load_xodr, resolve_route
from addt_dsl.runtime.roadmesh import Elevation

MAPS = Path(__file__).resolve().parents[3] / "examples" / "maps"


@pytest.fixture(scope="module")
def fabriksgatan():
    return load_xodr(MAPS / "fabriksgatan.xodr")


def _path(network, legs) -> RoutePath:
    roads = {g.road_id: (FastRoad(network.road(g.road_id)), Elevation(network.road(g.road_id))) for g in legs}
    return RoutePath("test", legs, roads)


def test_turns_pick_the_junction_connection(fabriksgatan):
    # Road 0 is driven against s in lane 1 (right-hand traffic) into junction 4.
    assert resolve_route(fabriksgatan, ["0", "left"], 1)[0] == ["0", "10", "3"]
    assert resolve_route(fabriksgatan, ["0", "straight"], 1)[0] == ["0", "9", "2"]
    assert resolve_route(fabriksgatan, ["0", "right"], 1)[0] == ["0", "8", "1"]
    # Naming the roads finds the connecting road; naming it too gives the same route.
    assert resolve_route(fabriksgatan, ["0", "3"], 1)[0] == ["0", "10", "3"]
    assert resolve_route(fabriksgatan, ["0", "10", "3"], 1)[0] == ["0", "10", "3"]


def test_legs_follow_lane_links_and_directions(fabriksgatan):
    _, legs = resolve_route(fabriksgatan, ["0", "left"], 1)
    assert [(g.road_id, g.direction, g.lane) for g in legs] == [("0", -1, 1), ("10", 1, -1), ("3", -1, 1)]
    assert legs[0].s_from == pytest.approx(fabriksgatan.road("0").length) and legs[0].s_to == 0.0


def test_bad_routes_say_what_the_map_has(fabriksgatan):
    with pytest.raises(RouteError) as err:
        resolve_route(fabriksgatan, ["0", "1", "2"], 1)
    assert err.value.stop == 2 and "does not lead to road 2" in err.value.message
    with pytest.raises(RouteError) as err:  # only lane 1 of road 0 turns left
        resolve_route(fabriksgatan, ["0", "left"], 3)
    assert "9" not in err.value.message and "10 from lanes 1" in err.value.hint
    with pytest.raises(RouteError) as err:
        resolve_route(fabriksgatan, ["0", "7"], 1)
    assert "junction 4" in err.value.hint and "(left, to road 3)" in err.value.hint
    with pytest.raises(RouteError):
        resolve_route(fabriksgatan, ["99"], -1)


def test_lane_sections_renumber_lanes():
    net = load_xodr(MAPS / "two_plus_one.xodr")
    _, legs = resolve_route(net, ["1"], -1, 0.0)
    assert [g.lane for g in legs] == [-1, -2, -2, -2, -1]
    assert [(g.s_from, g.s_to) for g in legs][1] == (125.0, 175.0)


def test_direct_junction_merges_the_ramp():
    net = load_xodr(MAPS / "soderleden.xodr")
    roads, legs = resolve_route(net, ["1", "5", "0"], -1)
    assert roads == ["1", "5", "0"]
    assert [(g.road_id, g.lane) for g in legs][:3] == [("1", -1), ("5", -1), ("0", -3)]


def test_path_is_continuous_through_the_junction(fabriksgatan):
    _, legs = resolve_route(fabriksgatan, ["0", "left"], 1)
    path = _path(fabriksgatan, legs)
    assert path.length == pytest.approx(sum(g.length_m for g in legs))
    u = np.arange(0.0, path.length, 0.5)
    pts = np.array([path.point(float(x), 0.0) for x in u])
    steps = np.hypot(np.diff(pts[:, 0]), np.diff(pts[:, 1]))
    assert steps.max() < 0.75  # no jump where legs meet (0.5 m of station, lane-centre curvature)
    assert np.abs(np.diff(pts[:, 2])).max() < 0.2  # heading unwrapped across legs
    # Driving direction: on road 0 (against s) the heading is the road's plus pi.
    _, _, h_road = fabriksgatan.road("0").reference_pose(80.0)
    assert math.remainder(path.reference_pose(path.station("0", 80.0))[2] - h_road - math.pi, math.tau) \
        == pytest.approx(0.0, abs=1e-5)  # the sampled view interpolates the heading


def test_path_projection_inverts_point(fabriksgatan):
    _, legs = resolve_route(fabriksgatan, ["0", "left"], 1)
    path = _path(fabriksgatan, legs)
    for u in np.linspace(1.0, path.length - 1.0, 37):
        for t in (-1.0, 0.0, 1.2):
            x, y, _ = path.point(float(u), t)
            assert path.project(x, y, float(u) + 3.0) == pytest.approx((u, t), abs=0.05)
            assert path.project(x, y) == pytest.approx((u, t), abs=0.05)


def test_path_lanes_are_in_driving_convention(fabriksgatan):
    _, legs = resolve_route(fabriksgatan, ["0", "left"], 1)
    path = _path(fabriksgatan, legs)
    u = path.station("0", 50.0)
    # Road 0's lanes 1..3 run with the route: -1..-3 in driving convention, -1 the route lane
    # (the one driving lane that way; -2, -3 are border and sidewalk); road lane -1 is oncoming: +1.
    assert path.lane_center_t(-1, u) == pytest.approx(0.0)
    assert path.lane_center_t(-2, u) < 0.0 < path.lane_center_t(1, u)
    assert path.driving_lane_ids(u) == (1, -1)
    assert path.lane_at(u, path.lane_center_t(1, u) + 0.3) == 1
