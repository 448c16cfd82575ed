"""A lane change onto a lane whose centre moves along the road (esmini's two_plus_one.xodr:
from s = 125 m a lane -1 grows from 0 to 3.5 m wide by s = 175 m, the lane offset with it, so
its centre moves from t = 0 to 1.75 m): the move is an offset from that centre, which the
agent follows, as esmini's lane change; then it holds the offset it ended at."""

from __future__ import annotations

import shutil

import pytest

from addt_dsl.compiler import compile_source
from addt_dsl.diagnostics import render_text
from addt_dsl.runtime.behaviors import blend
from addt_dsl.runtime.execute import execute
from addt_dsl.sweep import expand
from tests.conftest import ROOT

XODR = ROOT / "tests" / "data" / "esmini" / "xodr" / "two_plus_one.xodr"
SOURCE = """scenario widening {
  duration 5 s
  step 0.01 s
  road r import "two_plus_one.xodr" road 1
  ego car on r lane -2 at 300 m speed 0 m/s
  agent a car on r lane -2 at 125 m speed 20 m/s {
    behavior cruise speed 20 m/s
    at 0.5 s behavior lane_change to -1 duration 3 s shape cubic
  }
}
"""


def centre(s: float) -> float:
    """Lane -1's centre [m] at station s: half its width (the lane offset equals the width)."""
    ds = min(max(s - 125.0, 0.0), 50.0)
    return 0.5 * (0.0042 * ds ** 2 - 5.6e-05 * ds ** 3)


def test_a_lane_change_follows_the_moving_centre_of_its_lane(tmp_path):
    shutil.copy(XODR, tmp_path / XODR.name)
    result = compile_source(SOURCE, path=str(tmp_path / "widening.addt"), base_dir=tmp_path)
    assert result.ok, render_text(result.diagnostics, result.sources)
    trace = execute(expand(result.plan).specs[0]).trace
    a = trace.actors["a"]
    k = int(round(2.0 / 0.01))  # half way: s = 125 + 20 * 2 = 165 m
    assert a.s[k] == pytest.approx(165.0, abs=0.2)  # less what the move across takes
    # the centre there plus half of the offset it started with (at 0.5 s, s = 135 m: from
    # lane -2's centre, -1.75 m, to lane -1's there)
    k0 = int(round(0.5 / 0.01))
    start_offset = -1.75 - centre(a.s[k0])
    assert a.t[k] == pytest.approx(centre(a.s[k - 1]) + start_offset * (1.0 - blend("cubic", 0.5)), abs=0.005)
    # It ends in the lane's centre past s = 175 m (it ended at lane -1's centre where it
    # started, t = 0.18 m)
    assert a.t[-1] == pytest.approx(1.75, abs=1e-6)
    assert abs(a.t[-1] - a.t[int(round(4.0 / 0.01))]) < 1e-9  # held after the change
