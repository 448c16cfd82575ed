"""Network API: projections, lane queries, topology, inline roads."""

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from addt_dsl.road import (
    RoadCoords,
    arc,
    build_road,
    line,
    load_xodr,
    param_poly3,
    parse_xodr,
    spiral,
)

DATA = Path(__file__).resolve().parents[2] / "data" / "xodr"
NETWORKS = {p.name: load_xodr(p) for p in sorted(DATA.glob("*.xodr"))}


@st.composite
def lane_points(draw):
    name = draw(st.sampled_from(sorted(NETWORKS)))
    net = NETWORKS[name]
    road = net.road(draw(st.sampled_from(sorted(net.roads))))
    s = draw(st.floats(0.0, road.length, allow_nan=False))
    lanes = [i for i in road.lane_ids(s) if road.lane_width(i, s) > 1e-3]
    if not lanes:
        s = road.length / 2
        lanes = list(road.lane_ids(s))
    return name, road.id, draw(st.sampled_from(lanes)), s


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(lane_points())
def test_lane_center_round_trip(point):
    name, road_id, lane_id, s = point
    net = NETWORKS[name]
    x, y, _ = net.lane_center(road_id, lane_id, s)
    rc = net.to_road_coords(x, y)
    assert isinstance(rc, RoadCoords)
    assert (rc.road_id, rc.lane_id) == (road_id, lane_id)
    # curves_elevation.xodr's own geometry joints are discontinuous by up to 1.2e-5 m
    # (see tests/data/xodr/SOURCES.txt): a point on a joint projects within that gap.
    tol = 2e-5 if name == "curves_elevation.xodr" else 1e-6
    assert rc.s == pytest.approx(s, abs=tol)
    assert rc.t == pytest.approx(net.road(road_id).lane_center_t(lane_id, s), abs=tol)
    assert net.road(road_id).lane_offset(lane_id, x, y) == pytest.approx(0.0, abs=tol)


@pytest.mark.parametrize("name", ["curves_elevation.xodr", "jolengatan.xodr", "curve_r100.xodr"])
def test_projection_matches_brute_force(name):
    road = next(iter(NETWORKS[name].roads.values()))
    rng = np.random.default_rng(0)
    s_dense = np.linspace(0.0, road.length, 400_001)
    xd, yd, _ = road.reference_pose(s_dense)
    lo_x, hi_x, lo_y, hi_y = xd.min() - 60, xd.max() + 60, yd.min() - 60, yd.max() + 60
    px = rng.uniform(lo_x, hi_x, 300)
    py = rng.uniform(lo_y, hi_y, 300)
    s, t, f = road.project_array(px, py)
    rx, ry, _ = road.reference_pose(s)
    ours = np.hypot(px - rx, py - ry)
    brute = np.array([np.min(np.hypot(xd - a, yd - b)) for a, b in zip(px, py)])
    assert np.all(ours <= brute + 1e-9)  # never worse than a 3 mm-spaced exhaustive search
    np.testing.assert_allclose(np.hypot(f, t), ours, atol=1e-9)
    # scalar and vectorised paths agree
    for i in range(0, 300, 37):
        assert road.project(px[i], py[i]) == pytest.approx((s[i], t[i]), abs=1e-9)


def test_to_road_coords_outside_and_vectorised():
    net = NETWORKS["straight_500m.xodr"]
    road = net.road("1")
    lo, hi = road.road_band_t(100.0)
    rc = net.to_road_coords(100.0, hi + 2.0)
    assert rc.lane_id is None and rc.s == pytest.approx(100.0) and rc.t == pytest.approx(hi + 2.0)
    rc = net.to_road_coords(-5.0, -1.0)  # before the road start
    assert rc.lane_id is None and rc.s == 0.0
    xs = np.linspace(0.0, 500.0, 1001)
    res = net.to_road_coords_array(xs, np.full_like(xs, -1.0))
    assert set(res.road_id) == {"1"} and np.all(res.lane_id == -1)
    np.testing.assert_allclose(res.s, xs, atol=1e-9)
    np.testing.assert_allclose(res.t, -1.0, atol=1e-9)
    assert np.all(res.distance_off_road == 0.0)


def test_lane_offset_signed_and_vectorised():
    net = NETWORKS["curve_r100.xodr"]
    road = net.road("0")
    s = np.linspace(0.0, road.length, 200)
    x, y, h = road.lane_center(-1, s)
    # Shift 0.4 m to the left of the lane centre (normal of the centre curve).
    off = road.lane_offset(-1, x - 0.4 * np.sin(h), y + 0.4 * np.cos(h))
    np.testing.assert_allclose(off, 0.4, atol=1e-9)
    assert road.lane_offset(-1, float(x[10]), float(y[10])) == pytest.approx(0.0, abs=1e-9)
    # A lane missing at the projected s gives NaN rather than a misleading number.
    tpo = NETWORKS["two_plus_one.xodr"].road("1")
    assert math.isnan(tpo.lane_offset(-2, 50.0, -5.0))


def test_travel_direction_and_types():
    road = NETWORKS["straight_500m.xodr"].road("1")
    assert road.travel_direction(-1) == 1 and road.travel_direction(1) == -1
    assert set(road.driving_lane_ids(10.0)) <= set(road.lane_ids(10.0))
    assert all(road.lane_type(i, 10.0) == "driving" for i in road.driving_lane_ids(10.0))


# ---------------------------------------------------------------- topology

JUNCTION_MAP = """<?xml version="1.0"?>
<OpenDRIVE>
  <header revMajor="1" revMinor="6"/>
  {roads}
  <junction id="100" name="merge">
    <connection id="0" incomingRoad="1" connectingRoad="10" contactPoint="start">
      <laneLink from="-1" to="-1"/>
    </connection>
    <connection id="1" incomingRoad="2" connectingRoad="11" contactPoint="start">
      <laneLink from="-1" to="-1"/>
    </connection>
  </junction>
</OpenDRIVE>
"""
ROAD = """<road id="{id}" length="{length}" junction="{junction}">
    <link>{link}</link>
    <planView><geometry s="0" x="{x}" y="{y}" hdg="{hdg}" length="{length}">{geom}</geometry></planView>
    <lanes><laneSection s="0"><center><lane id="0" type="none"/></center>
      <right><lane id="-1" type="driving"><width sOffset="0" a="3.5" b="0" c="0" d="0"/></lane></right>
    </laneSection></lanes>
  </road>"""


def _junction_network():
    def road(id, x, y, hdg, length, link, geom="<line/>", junction="-1"):
        return ROAD.format(id=id, x=x, y=y, hdg=hdg, length=length, link=link, geom=geom, junction=junction)

    smooth = '<paramPoly3 pRange="normalized" aU="0" bU="50" cU="0" dU="0" aV="0" bV="0" cV="30" dV="-20"/>'
    roads = "\n".join([
        road(1, 0, 0, 0, 100, '<successor elementType="junction" elementId="100"/>'),
        road(2, 0, -10, 0, 100, '<successor elementType="junction" elementId="100"/>'),
        road(10, 100, 0, 0, 50, '<predecessor elementType="road" elementId="1" contactPoint="end"/>'
             '<successor elementType="road" elementId="3" contactPoint="start"/>', junction="100"),
        road(11, 100, -10, 0, 51, '<predecessor elementType="road" elementId="2" contactPoint="end"/>'
             '<successor elementType="road" elementId="3" contactPoint="start"/>', geom=smooth, junction="100"),
        road(3, 150, 0, 0, 100, '<predecessor elementType="junction" elementId="100"/>'
             '<successor elementType="road" elementId="4" contactPoint="end"/>'),
        road(4, 350, 0, math.pi, 100, '<successor elementType="road" elementId="3" contactPoint="end"/>'),
    ])
    return parse_xodr(JUNCTION_MAP.format(roads=roads), source_name="merge.xodr")


def test_links_junction_and_chain():
    net = _junction_network()
    r1 = net.road("1")
    assert (r1.successor.element_type, r1.successor.element_id, r1.successor.contact_point) == ("junction", "100", None)
    assert net.road("10").is_junction_road and not r1.is_junction_road
    assert net.junctions["100"].connections[1].lane_links == ((-1, -1),)
    assert net.next_roads("1") == [("10", "start")]
    assert net.next_road("2", "end") == ("11", "start")
    assert net.next_road("11") == ("3", "start")
    assert net.next_road("3") == ("4", "end")  # road 4 runs the other way
    assert net.next_road("1", "start") is None
    assert net.follow_chain("2") == [("2", 1), ("11", 1), ("3", 1), ("4", -1)]
    assert net.follow_chain("4", "end") == [("4", 1), ("3", -1)]  # junction has no entry from road 3
    # Roads meet where the links say they do.
    for a, b in [("1", "10"), ("10", "3"), ("2", "11"), ("11", "3")]:
        ra, rb = net.road(a), net.road(b)
        assert ra.reference_pose(ra.length)[:2] == pytest.approx(rb.reference_pose(0.0)[:2], abs=1e-9)
    assert net.road("3").reference_pose(100.0)[:2] == pytest.approx(net.road("4").reference_pose(100.0)[:2], abs=1e-9)
    # The merge's curved connecting road is picked for points on it.
    x, y, _ = net.lane_center("11", -1, 25.0)
    assert net.to_road_coords(x, y).road_id == "11"
    with pytest.raises(ValueError):
        net.next_roads("1", "middle")
    with pytest.raises(KeyError, match="no road '99'"):
        net.road("99")


# ---------------------------------------------------------------- inline roads


def test_build_road_chains_segments_tangent_continuously():
    segs = [line(50.0), spiral(20.0, 0.0, 0.02), arc(30.0, 0.02), spiral(20.0, 0.02, 0.0),
            param_poly3(30.0, bU=1.0, bV=0.3, cV=0.01), line(10.0)]
    net = build_road("r", segs, left_lanes=1, right_lanes=2, lane_width_m=3.5, lane_offset_m=0.5,
                     start=(10.0, 20.0, 0.3))
    road = net.road("r")
    assert road.length == pytest.approx(160.0)
    assert road.reference_pose(0.0) == pytest.approx((10.0, 20.0, 0.3))
    gs = road.geometries
    for g0, g1 in zip(gs, gs[1:]):
        x, y, h = g0.pose(g0.s0 + g0.length)
        x1, y1, h1 = g1.pose(g1.s0)
        assert math.hypot(x - x1, y - y1) < 1e-9
        assert abs(math.remainder(h - h1, 2 * math.pi)) < 1e-12
    assert road.lane_ids(80.0) == (1, -1, -2) == road.driving_lane_ids(80.0)
    assert net.lane_width("r", -2, 155.0) == 3.5
    assert road.lane_center_t(-1, 3.0) == pytest.approx(0.5 - 1.75)
    assert road.lane_center_t(1, 3.0) == pytest.approx(0.5 + 1.75)
    assert net.curvature("r", 85.0) == pytest.approx(0.02)
    assert net.elevation("r", 85.0) == 0.0


def test_build_road_u_turn_closed_form():
    net = build_road("u", [line(100.0), arc(100.0 * math.pi, 0.01), line(100.0)], 1, 1, 3.0)
    assert net.reference_pose("u", net.road("u").length) == pytest.approx((0.0, 200.0, math.pi), abs=1e-9)
    # Right lane of a left turn is on the outside: radius 101.5 m.
    x, y, h = net.lane_center("u", -1, 100.0 + 50.0 * math.pi)
    assert (x, y) == pytest.approx((100.0 + 101.5, 100.0), abs=1e-9)


@pytest.mark.parametrize(
    "kwargs",
    [
        dict(segments=[], left_lanes=1, right_lanes=1, lane_width_m=3.0),
        dict(segments=[line(10.0)], left_lanes=0, right_lanes=0, lane_width_m=3.0),
        dict(segments=[line(10.0)], left_lanes=1, right_lanes=1, lane_width_m=0.0),
        dict(segments=[line(10.0)], left_lanes=-1, right_lanes=1, lane_width_m=3.0),
    ],
)
def test_build_road_rejects_bad_input(kwargs):
    with pytest.raises(ValueError):
        build_road("bad", **kwargs)


@pytest.mark.parametrize("factory", [lambda: line(0.0), lambda: arc(-1.0, 0.1), lambda: spiral(float("nan"), 0, 0)])
def test_segment_factories_validate(factory):
    with pytest.raises(ValueError):
        factory()
