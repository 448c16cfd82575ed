"""`lane_id(A)`: the driving lane an actor is in, in triggers and oracles, recorded only in
runs that read it."""

from __future__ import annotations

import numpy as np

from tests.sim.kit import first_run


SOURCE = """scenario lanes {
  duration 4 s
  road r {
    line length 400 m
    lanes right 3 width 3.5 m
  }
  ego car on r lane -3 at 10 m speed 0 m/s
  agent a car on r lane -1 at 60 m speed 10 m/s {
    at 0.5 s behavior lane_change to -2 duration 1 s
    go: when lane_id(a) == -2 then behavior cruise speed 20 m/s
  }
  expect {
    moved: eventually lane_id(a) == -2
    stays: always lane_id(ego) == -3
  }
}
"""


def _run(source):
    return first_run(source, "lanes.addt")


def test_lane_id_in_a_trigger_and_in_oracles():
    run = _run(SOURCE)
    assert run.passed, run.failures
    lanes, t = run.trace.lanes["a"], run.trace.actors["a"].t
    # lane -1 until the move passes the boundary (t = -3.5 m) at the nearest centre, then -2
    first = int(np.argmax(lanes == -2))
    assert set(lanes[:first]) == {-1.0} and set(lanes[first:]) == {-2.0}
    assert t[first] < -3.5 <= t[first - 1]  # (at -3.5 m both centres are as near: the first, -1)
    # the step fires at the first sample in lane -2, then the speed goes up
    go = next(e for e in run.trace.events if e.kind == "trigger" and e.detail.get("behavior") == "cruise")
    assert abs(go.time_s - run.trace.time[first]) < 1e-9


def test_runs_that_do_not_read_lane_ids_do_not_record_them():
    run = _run(SOURCE.replace("go: when lane_id(a) == -2 then", "at 3 s").replace(
        "moved: eventually lane_id(a) == -2", "moved: eventually t(a) < -5 m").replace(
        "stays: always lane_id(ego) == -3", "stays: always t(ego) < -8 m"))
    assert run.passed and run.trace.lanes == {}
