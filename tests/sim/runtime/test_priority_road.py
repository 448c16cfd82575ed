"""A priority road (StVO 306) in closed loop over two junctions (runtime/signs.py
`junction_rule`, the `bev` stack's gap rule). CARLA's Town01 (tests/data/carla, no traffic
light controllers declared: its lights are dark): the ego drives south on road 21 lane -1,
straight through junction 171 (route stations 34.91-56.91 m) and junction 306
(108.60-130.60 m) onto road 23. A side car comes west on road 4 (lane 1) towards junction
306, crossing the ego's path, and brakes to a stop before it. A sign on road 21 (s 10 m,
facing the ego's lane) governs junction 171 only as 301; as 306 it makes road 21 and on a
priority road, so the ego has priority at junction 306 too."""

from pathlib import Path

import numpy as np
import pytest

from addt_dsl.compiler import compile_source
from addt_dsl.runtime.execute import execute
from addt_dsl.sweep import expand

pytestmark = pytest.mark.slow

TOWN = Path(__file__).resolve().parents[2] / "data" / "carla" / "maps" / "Town01.xodr"
SECOND = (108.60, 130.60)  # [m] the ego's route stations of junction 306 (entry, exit)
SIGN = '<signal s="10.0" t="-4.0" id="9000" dynamic="no" orientation="+" type="{type}"/>'


def _run(tmp_path, sign_type: str):
    text = TOWN.read_text()
    start = text.index("<signals>", text.index('<road name="Road 21"')) + len("<signals>")
    (tmp_path / "town.xodr").write_text(text[:start] + SIGN.format(type=sign_type) + text[start:])
    source = """
scenario priority_road {
  duration 25 s
  road town import "town.xodr" road 21
  ego car on town route 21 -> straight -> 22 -> straight -> 23 lane -1 at 5 m speed 8 m/s goal 140 m {
    stack bev cruise_speed 8 m/s
  }
  agent side car on town route 4 -> right -> 22 lane 1 at 100 m speed 8 m/s {
    behavior cruise speed 8 m/s
    when s(side) > 210 m then behavior brake decel 3 m/s^2
  }
  expect {
    no collision
    reach goal within 25 s
  }
}
"""
    result = compile_source(source, "priority_road.addt", base_dir=tmp_path)
    assert result.ok, [str(d) for d in result.diagnostics]
    out = execute(expand(result.plan).specs[0])
    assert out.status == "ok", out.error
    assert all(v.passed for v in out.verdicts), out.verdicts
    ego, side = out.trace.actors["ego"], out.trace.actors["side"]
    # The side car stops east of junction 306 (its entry at x 101.4 m) in every run.
    assert side.x.min() > 101.4 and side.speed[-1] < 0.1
    return ego


def test_a_priority_road_keeps_priority_at_the_second_junction_a_301_does_not(tmp_path):
    ego = _run(tmp_path, "306")
    # Main before the priority road slowed the ego to 4.2 m/s for the braking side car.
    assert ego.speed.min() > 7.9
    # A 301 there: at junction 306 the ego gives way, slowing for the side car before the entry.
    ego = _run(tmp_path, "301")
    k = int(np.argmin(ego.speed))
    assert ego.speed[k] < 5.0
    assert 56.91 < ego.s[k] + 0.5 * ego.length_m < SECOND[0]
