"""Passing a standing obstacle with the bev stack: within the lane when the obstacle
leaves room (a car parked 0.9 m into the lane), into a free lane of the same direction,
and never through the oncoming lane (the stack does not pass through it: see
docs/stack.md)."""

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
