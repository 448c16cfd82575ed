"""Event priorities run: imported synthetic files (tests/unit/interop/priority_kit.py) against
the speeds esmini's Event::Start gives them, computed by hand."""

import pytest

from addt_dsl.runtime.execute import execute
from addt_dsl.sweep import expand
from tests.unit.interop.priority_kit import at, imported, speed

pytestmark = pytest.mark.slow


def car_speed(got):
    assert got.plan is not None, [str(d) for d in got.diagnostics if d.is_error]
    out = execute(expand(got.plan).specs[0])
    assert out.status == "ok", out.error
    car = out.trace.actors["Car"]
    return lambda t: float(car.speed[int(round(t / out.trace.period_s))])


def test_a_skip_event_starts_only_once_the_running_event_of_its_maneuver_has_ended(tmp_path):
    # The ramp 10 -> 20 m/s over 10 s runs from 1 s to 11 s. The skip event's time (past 2 s)
    # holds from 2 s on, and esmini asks it again at each step: skipped while the ramp runs,
    # started as it ends; then a step to 5 m/s.
    v = car_speed(imported(tmp_path, speed("ramp", "override", 20, at(1)),
                           speed("low", "skip", 5, at(2), shape="step")))
    assert v(2.5) == pytest.approx(11.5, abs=0.05)
    assert v(10.5) == pytest.approx(19.5, abs=0.05)
    assert v(11.5) == pytest.approx(5.0, abs=1e-6) and v(13.5) == pytest.approx(5.0, abs=1e-6)


def test_an_override_during_a_speed_ramp_holds_its_own_speed(tmp_path):
    # The override at 4 s (the ramp at 13 m/s) sets 14 m/s; the ramp ends with it and never
    # reaches 20 m/s.
    v = car_speed(imported(tmp_path, speed("ramp", "override", 20, at(1)),
                           speed("hold", "override", 14, at(4), shape="step")))
    assert v(3.95) == pytest.approx(12.95, abs=0.05)
    assert v(4.5) == pytest.approx(14.0, abs=1e-6) and v(13.5) == pytest.approx(14.0, abs=1e-6)
