"""The planner's prediction in closed loop: junction_cyclist's latest trigger (10 m), where
the rider at the kerb turns across the road the ego turns into and sets off at 1 m/s^2
while the ego, at 7.7 m/s, is 9 m short. Its tracked velocity passes the crossing test
(0.5 m/s) only 0.5 s later, when the ego (2.5 m from the rider's box, 4 m to stop) can no
longer stop; the rider turned across at rest is predicted setting off at 1.5 m/s^2 from the
plan after it turns, when the ego can (3.7 m at mu g, 6.3 m left)."""

import pytest

from addt_dsl.compiler import compile_file
from addt_dsl.runtime.execute import execute
from addt_dsl.sweep import expand
from tests.conftest import EXAMPLES

pytestmark = pytest.mark.slow


def test_junction_cyclist_latest_trigger_stops_short_of_the_rider():
    result = compile_file(EXAMPLES / "junction_cyclist.addt")
    spec = expand(result.plan).specs[0]
    assert spec.params["trigger_at"] == pytest.approx(10.0)
    out = execute(spec)
    assert out.passed, out.verdicts
    trigger = next(e.time_s for e in out.trace.events if e.kind == "trigger" and e.detail["actor"] == "rider")
    brake = next(e.time_s for e in out.trace.events if e.kind == "emergency_brake" and e.detail["on"])
    assert 0.0 < brake - trigger <= 0.1  # the first plan after the rider turns (10 Hz)
