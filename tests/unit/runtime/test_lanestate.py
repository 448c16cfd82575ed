"""`wrong_way(A)` and `off_lanes(A)` (runtime/lanestate.py): CARLA ScenarioRunner's WrongLaneTest
and OnSidewalkTest states, on hand-built cases."""

from pathlib import Path

import numpy as np

from addt_dsl.compiler import compile_source
from addt_dsl.road.xodr import parse_xodr
from addt_dsl.runtime.execute import execute
from addt_dsl.runtime.fastroad import FastRoad
from addt_dsl.runtime.lanestate import against_traffic, off_lanes
from addt_dsl.runtime.signals import compute_signals
from addt_dsl.sweep import expand

# Lanes at every s: 3 border [4.75, 10.75], 2 shoulder [3.07, 4.75], 1 and -1 driving (3.07 m
# wide), -2 shoulder [-4.75, -3.07], -3 border [-10.75, -4.75]; right-hand traffic.
XODR = (Path(__file__).resolve().parents[2] / "data" / "xodr" / "straight_500m.xodr").read_text()
LENGTH, WIDTH = 4.5, 1.8


def _road(text=XODR):
    network = parse_xodr(text)
    return FastRoad(network.road(next(iter(network.roads))))


def _off(path, t, was=False, s=100.0):
    x, y, h = path.point(s, t)
    return off_lanes(path, s, t, x, y, h, LENGTH, WIDTH, was)


def test_off_lanes_on_shoulder_border_and_beyond():
    path = _road()
    assert not _off(path, -1.5)  # in its driving lane
    assert not _off(path, -3.5)  # centre on the shoulder, a corner (t = -2.6) in the driving lane
    # Centre on the shoulder (corners at -3.1 and -4.9: shoulder, border), or on the border: inside
    # a lane that is neither a sidewalk nor driving, no corner on a sidewalk (ScenarioRunner's
    # case 2.4, the waypoint within half a lane width).
    assert not _off(path, -4.0)
    assert not _off(path, -6.0)
    assert _off(path, -11.0)  # past the border lane's outer edge (-10.75 m): off every lane
    assert _off(path, 11.0)


def test_off_lanes_on_a_sidewalk():
    lanes = XODR.split('<lane id="-2" type="shoulder"')
    path = _road(lanes[0] + '<lane id="-2" type="sidewalk"' + lanes[1])
    assert _off(path, -3.3)  # the centre on the sidewalk, though a corner is in the driving lane
    assert not _off(path, -2.9)  # the centre in the driving lane, a corner on the sidewalk
    assert _off(path, -5.0)  # centre on the border, a corner (-4.1 m) on the sidewalk
    assert not _off(_road(), -5.0)  # that corner on a shoulder


def test_off_lanes_keeps_its_state_only_beside_a_junctions_driving_lane():
    path = _road()
    assert _off(path, -11.0, was=False) and not _off(path, -1.5, was=True)
    # Every lane driving: past the edge the nearest lane is a driving one (ScenarioRunner's case 3):
    # not off, except in a junction, where the waypoint is too far to tell and the state stays.
    paved = XODR.replace('type="border"', 'type="driving"').replace('type="shoulder"', 'type="driving"')
    assert not _off(_road(paved), -11.0, was=True)
    junction = _road(paved.replace('id="1" junction="-1"', 'id="1" junction="7"'))
    assert _off(junction, -11.0, was=True) and not _off(junction, -11.0, was=False)
    assert not _off(junction, -1.5, was=True)
    assert not against_traffic(junction, 100.0, 1.5)  # no wrong way inside a junction


def test_against_traffic_by_lane():
    path = _road()
    assert not against_traffic(path, 100.0, -1.5)
    assert against_traffic(path, 100.0, 1.5)
    assert against_traffic(path, 100.0, 0.01)  # nearer lane 1's centre
    assert not against_traffic(path, 100.0, -0.01)


def test_wrong_way_from_the_sample_the_centre_crosses_the_centre_line():
    text = """
scenario into_oncoming {
  duration 5 s
  road r {
    line length 300 m
    lanes left 1 right 1
  }
  ego car on r lane -1 at 20 m speed 10 m/s {
    behavior cruise speed 10 m/s
    at 1 s behavior lane_change to 1 duration 3 s
  }
  agent marker car on r lane -1 at 200 m speed 0 m/s {
    when wrong_way(ego) then behavior cruise speed 5 m/s
  }
  expect {
    always not wrong_way(ego)
    always not off_lanes(ego)
  }
}
"""
    result = compile_source(text, "ww.addt")
    assert result.plan is not None, [str(d) for d in result.diagnostics]
    out = execute(expand(result.plan).specs[0])
    trace = out.trace
    sig = compute_signals(trace, {"wrong_way(ego)", "off_lanes(ego)"})
    # From the sample on the line (t = 0 m: lane 1's, as OpenDRIVE and `lane_id` have it).
    crossed = int(np.argmax(trace.actors["ego"].t >= 0.0))
    assert crossed > 0
    wrong = sig["wrong_way(ego)"] > 0
    assert not wrong[:crossed].any() and wrong[crossed:].all()
    assert (sig["off_lanes(ego)"] < 0).all()
    # A condition reads it at the sample it turns true.
    fired = [e.time_s for e in trace.events_of("trigger") if e.detail.get("actor") == "marker"]
    assert fired == [trace.time[crossed]]
    verdicts = [(v.passed, v.first_violation_s) for v in out.verdicts]
    assert verdicts == [(False, trace.time[crossed]), (True, None)]


def test_against_traffic_on_a_lane_driven_against_s():
    # A path along lane 1 (driven against s): its own lane is with the traffic, lane -1 against.
    from addt_dsl.road.route import Leg
    from addt_dsl.runtime.roadmesh import Elevation
    from addt_dsl.runtime.path import RoutePath

    network = parse_xodr(XODR)
    road_id = next(iter(network.roads))
    path = RoutePath("r", [Leg(road_id, -1, 400.0, 100.0, 1)],
                     {road_id: (FastRoad(network.road(road_id)), Elevation(network.road(road_id)))})
    assert not against_traffic(path, 50.0, 0.0)  # its lane's centre (path t = 0)
    assert against_traffic(path, 50.0, 3.07)  # lane -1's centre, to the driver's left
    # To the driver's right lie lane 1's shoulder and border (road t 3.07 to 10.75 m): the centre
    # on the border, its corners on the shoulder and the border, is inside a lane (not off).
    x, y, h = path.point(50.0, -3.5)
    assert not off_lanes(path, 50.0, -3.5, x, y, h, LENGTH, WIDTH, False)
    x, y, h = path.point(50.0, -11.0)
    assert off_lanes(path, 50.0, -11.0, x, y, h, LENGTH, WIDTH, False)
