"""`at_road_end stop`: an agent (or a scripted ego) is held at the end of its road at speed 0,
as esmini holds its entities; without it an actor goes on straight past the end."""

from __future__ import annotations

import numpy as np
import pytest

from addt_dsl.compiler import compile_source
from addt_dsl.diagnostics import render_text
from addt_dsl.runtime.execute import execute
from addt_dsl.sweep import expand

SOURCE = """
scenario road_end {
  duration 6 s
  road r {
    line length 100 m
    lanes right 2 left 1
  }
  ego car on r lane -2 at 10 m speed 10 m/s at_road_end stop {
    behavior cruise speed 10 m/s
  }
  agent stopper car on r lane -1 at 60 m speed 10 m/s at_road_end stop
  agent oncoming car on r lane 1 at 40 m speed 10 m/s at_road_end stop
  agent goer car on r lane -2 at 50 m speed 10 m/s
}
"""


def test_actors_stop_at_the_end_of_their_road_only_when_told():
    result = compile_source(SOURCE, path="road_end.addt")
    assert result.ok, render_text(result.diagnostics, result.sources)
    trace = execute(expand(result.plan).specs[0]).trace
    k = int(round(4.5 / 0.01))  # the stopper reached s = 100 m at 4 s; the oncoming one s = 0 at 4 s
    stopper, oncoming, goer, ego = (trace.actors[n] for n in ("stopper", "oncoming", "goer", "ego"))
    assert np.all(stopper.speed[k:] == 0.0) and stopper.s[k:] == pytest.approx(100.0)
    assert stopper.speed[k - 60] == 10.0  # (moving until its end)
    assert np.all(oncoming.speed[k:] == 0.0)
    x_end = oncoming.x[k]
    assert np.all(oncoming.x[k:] == x_end) and x_end == pytest.approx(0.0, abs=1e-6)  # held at s = 0
    assert goer.s[-1] > 100.0 and goer.speed[-1] == 10.0  # `go`, the default: on past the end
    assert ego.s[-1] == pytest.approx(70.0, abs=0.2)  # (10 m + 60 m: not there yet)
