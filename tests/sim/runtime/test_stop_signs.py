"""Stop signs of a map in closed loop: the `bev` stack stops the ego at their lines and goes
on; `stop_sign(A)` and `no stop_sign` judge who stopped (runtime/signs.py)."""

from pathlib import Path

import numpy as np
import pytest

from addt_dsl.compiler import compile_source
from addt_dsl.runtime.execute import execute
from addt_dsl.sweep import expand

pytestmark = pytest.mark.slow

MAP = Path(__file__).resolve().parents[2] / "data" / "xodr" / "straight_500m.xodr"
# A stop sign for traffic along +s (lane -1) at s = 150 m, and one for the other way at 300 m.
SIGNS = """<signals>
            <signal s="150.0" t="-4.0" id="900" name="Sign_Stop" dynamic="no" orientation="+" zOffset="2.0"
                    country="OpenDRIVE" type="206" subtype="-1" height="0.9" width="0.9"/>
            <signal s="300.0" t="4.0" id="901" name="Sign_Stop" dynamic="no" orientation="-" zOffset="2.0"
                    country="OpenDRIVE" type="206" subtype="-1" height="0.9" width="0.9"/>
        </signals>"""

SOURCE = """
scenario stop_sign {
  duration 24 s
  road main import "signs.xodr" road 1
  ego car on main lane -1 at 20 m speed 10 m/s {
    stack bev cruise_speed 10 m/s
  }
  agent runner car on main lane -1 at 60 m speed 10 m/s {
    behavior cruise speed 10 m/s
  }
  expect {
    no collision
    no stop_sign
    runner_stops: always stop_sign(runner) >= 0 m
  }
}
"""


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("signs")
    text = MAP.read_text()
    assert "<signals>\n        </signals>" in text
    (folder / "signs.xodr").write_text(text.replace("<signals>\n        </signals>", SIGNS))
    result = compile_source(SOURCE, "stop_sign.addt", base_dir=folder)
    assert result.ok, [str(d) for d in result.diagnostics]
    out = execute(expand(result.plan).specs[0])
    assert out.status == "ok", out.error
    return out


def test_the_ego_stops_at_the_line_then_goes_on(run):
    ego = run.trace.actors["ego"]
    front = ego.s + 0.5 * ego.length_m
    before = front <= 150.0
    k = int(np.argmin(np.where(before, ego.speed, np.inf)))
    assert ego.speed[k] < 0.05 and 147.0 <= front[k] <= 150.0  # stood within 3 m before the line
    assert front[-1] > 200.0  # and went on (the sign at 300 m faces the other way)
    events = [e for e in run.trace.events if e.kind == "stop_sign"]
    assert len(events) == 1 and events[0].detail["station_m"] == pytest.approx(150.0, abs=1e-6)
    v = {x.name: x for x in run.verdicts}
    assert v["no_collision"].passed and v["no_stop_sign"].passed


def test_a_car_that_drives_through_runs_the_sign(run):
    # The runner's front: 60 m + half its length + 10 m/s t; it crosses 150 m at
    # t = (150 - 60 - L/2) / 10 without stopping (agents do not stop at signs).
    runner = run.trace.actors["runner"]
    t_cross = (150.0 - 60.0 - 0.5 * runner.length_m) / 10.0
    v = {x.name: x for x in run.verdicts}["runner_stops"]
    assert not v.passed
    assert v.first_violation_s == pytest.approx(t_cross, abs=0.011)
    assert v.robustness == pytest.approx(-30.0, abs=0.11)  # the margin runs to 30 m past the line
    margin = run.trace.stop_margin["runner"]
    k = int(np.argmax(runner.s + 0.5 * runner.length_m > 150.0))
    assert margin[k - 1] >= 0.0 > margin[k]
