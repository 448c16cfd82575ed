"""Passing a standing obstacle with the bev stack: within the lane when the obstacle
leaves room (a car parked 0.9 m into the lane), into a free lane of the same direction,
and through the oncoming lane only when it is seen clear for the whole manoeuvre (CARLA's
Slalom on a written road; docs/stack.md's passing rule), never into oncoming traffic."""

import pytest

from addt_dsl.compiler import compile_source
from addt_dsl.runtime.execute import execute
from addt_dsl.sweep import expand

pytestmark = pytest.mark.slow

ROAD = """
scenario pass_it {
  duration 20 s
  road r {
    line length 500 m
    lanes LANES width 3.5 m
  }
  ego car on r lane -1 at 20 m speed 12 m/s goal 250 m {
    stack bev cruise_speed 12 m/s
  }
  agent parked car on r lane -1 at 150 m offset OFFSET speed 0 m/s
  ONCOMING
  expect {
    no collision
    reach goal within 20 s
  }
}
"""


def _run(lanes: str, offset: str, oncoming: str = ""):
    text = ROAD.replace("LANES", lanes).replace("OFFSET", offset).replace("ONCOMING", oncoming)
    result = compile_source(text, "pass.addt")
    assert result.ok, [d.message for d in result.diagnostics]
    return execute(expand(result.plan).specs[0])


def test_a_car_parked_half_in_the_lane_is_passed_within_the_lane():
    """The parked car (1.9 m wide, centre 1.8 m right of the lane's) takes 0.9 m of the
    3.5 m lane: the ego moves left within its lane and passes (it stopped 23 m short)."""
    out = _run("right 1 left 1", "-1.8 m")
    assert out.passed, out.verdicts
    ego = out.trace.actors["ego"]
    # Its left side stays within 0.3 m past the centre line (t = 0; lane -1's centre -1.75 m).
    assert (ego.t + 0.5 * ego.width_m).max() < 0.3 + 0.05
    assert ego.t.max() > -1.75 + 0.4  # it did move over
    assert abs(ego.t[-1] + 1.75) < 0.2  # and back to the lane centre


def test_a_car_blocking_most_of_the_lane_is_passed_in_the_free_lane_beside():
    out = _run("right 2", "-1.0 m")
    assert out.passed, out.verdicts
    ego = out.trace.actors["ego"]
    assert ego.t.min() < -4.5  # in lane -2 (centre at t = -5.25 m) to pass


def test_never_into_the_oncoming_lane():
    """The parked car blocks the lane; an oncoming car comes: the ego waits behind the
    parked car, its left side never over the centre line by more than the in-lane margin."""
    out = _run("right 1 left 1", "0 m", "agent oncoming car on r lane 1 at 300 m speed 12 m/s {\n"
                                       "    behavior cruise speed 12 m/s\n  }")
    verdicts = {v.name: v.passed for v in out.verdicts}
    assert verdicts["no_collision"]
    ego = out.trace.actors["ego"]
    assert (ego.t + 0.5 * ego.width_m).max() < 0.3 + 0.05


# CARLA's Slalom (tests/data/carla/xosc/Slalom.xosc): containers 2 m long, 1 m wide (the
# catalogue obstacle's width), 1.7 m tall, in the ego's lane of a two-way road. Here three,
# centred in the lane (no room to pass within it), 12 m apart (passed as one group), with a
# lidar that sees a car head-on to 200 m (0.25 deg rays: `bev.lidar_sight`).
SLALOM = """
scenario slalom_like {
  duration 40 s
  road r {
    line length 500 m
    lanes right 1 left 1 width 3.5 m
  }
  ego car on r lane -1 at 20 m speed 8 m/s goal 260 m {
    stack bev cruise_speed 8 m/s
    SENSOR
  }
  agent c1 obstacle on r lane -1 at 120 m length 2 m width 1 m height 1.7 m
  agent c2 obstacle on r lane -1 at 132 m length 2 m width 1 m height 1.7 m
  agent c3 obstacle on r lane -1 at 144 m length 2 m width 1 m height 1.7 m
  ONCOMING
  expect {
    no collision
    reach goal within 40 s
  }
}
"""
FAR_LIDAR = "sensor lidar rays 1440 channels 5 vfov 4 deg pitch 2 deg range 200 m"


def _slalom(sensor: str = FAR_LIDAR, oncoming: str = ""):
    text = SLALOM.replace("SENSOR", sensor).replace("ONCOMING", oncoming)
    result = compile_source(text, "slalom.addt")
    assert result.ok, [d.message for d in result.diagnostics]
    return execute(expand(result.plan).specs[0])


def test_slalom_passes_through_the_empty_oncoming_lane_and_returns():
    out = _slalom()
    assert out.passed, out.verdicts
    ego = out.trace.actors["ego"]
    assert ego.t.max() > 1.0  # in the oncoming lane (centre at t = +1.75 m) to pass
    passing = ego.t > 0.0
    # Over the line only around the containers (rears 119-143 m): it returns after them.
    assert ego.s[passing].min() > 95.0 and ego.s[passing].max() < 175.0
    assert abs(ego.t[-1] + 1.75) < 0.2


def test_slalom_stays_behind_when_its_lidar_cannot_see_far_enough():
    """The default lidar sees a car head-on to 57 m; passing 3 containers takes ~60 m and
    ~8 s, in which an unseen car at 8 m/s comes ~80 m: the ego stays in its lane."""
    out = _slalom(sensor="")
    ego = out.trace.actors["ego"]
    assert {v.name: v.passed for v in out.verdicts}["no_collision"]
    assert (ego.t + 0.5 * ego.width_m).max() < 0.05  # its side stays in its lane
    assert ego.s.max() < 119.0  # behind the first container


def test_slalom_waits_for_the_oncoming_car_then_passes():
    """An oncoming car at 10 m/s is about 90 m off when the ego nears the containers: the ego
    waits in its lane (its side 0.3 m from the centre line, where it sees past them) until
    the car is by, then passes; it is never over the line while the car is ahead of it.
    Clearance oracle: 1 m (two cars 1.9 m wide in the centres of 3.5 m lanes pass 1.6 m
    apart; the waiting ego stands up to 0.5 m nearer the line)."""
    out = _slalom(oncoming="agent oncoming car on r lane 1 at 260 m speed 10 m/s {\n"
                           "    behavior cruise speed 10 m/s\n  }\n"
                           "  expect { clear_of_oncoming: always clearance(oncoming) > 1 m }")
    verdicts = {v.name: v.passed for v in out.verdicts}
    assert all(verdicts.values()), verdicts
    ego, car = out.trace.actors["ego"], out.trace.actors["oncoming"]
    # The road runs along x: the car (driving against s) has not gone by while its rear is
    # ahead of the ego's rear.
    ahead = car.x + 0.5 * car.length_m > ego.x - 0.5 * ego.length_m
    assert ahead[:100].all() and not ahead[-100:].any()
    assert (ego.t[ahead] + 0.5 * ego.width_m).max() < 0.05  # its side stays in its lane meanwhile
    assert ego.t.max() > 1.0  # and then it passes
