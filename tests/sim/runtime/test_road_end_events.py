"""What esmini does at a road's end, as lane_change_simple.xosc uses it (esmini 3.6,
ScenarioEngine::step and TeleportAction): `road_end(A)` is 0 while `at_road_end stop` holds A
at the end; its speed drops to 0 the step after it arrived, and a speed behaviour that had
completed lets go (teleported away, it stands); a teleport does not move the actor in its
step; `rising C for D` is an edge of the held condition; a `repeat N` step has ended only
after its N-th run; a cubic change over a time is stretched to `max_accel`."""

from __future__ import annotations

import numpy as np
import pytest

from addt_dsl.compiler import compile_source
from addt_dsl.diagnostics import render_text
from addt_dsl.runtime.execute import execute
from addt_dsl.runtime.signals import STEP_ENDED, STEP_STARTED
from addt_dsl.sweep import expand

SOURCE = """
scenario road_end_events {
  duration 9 s
  road r {
    line length 100 m
    lanes right 2
  }
  road long {
    line length 300 m
    lanes right 1
  }
  ego car on long lane -1 at 200 m speed 0 m/s {
    stack bev cruise_speed 0 m/s
  }
  agent looper car on r lane -1 at 60 m speed 10 m/s at_road_end stop {
    behavior cruise speed 10 m/s
    back: when rising road_end(looper) <= 0 m for 1 s repeat 2 then behavior teleport s 20 m t -1.75 m
  }
  agent quick car on r lane -2 at 60 m speed 10 m/s at_road_end stop {
    jump: when rising road_end(quick) <= 0 m then behavior teleport s 10 m t -5.25 m
  }
  agent ramp car on long lane -1 at 0 m speed 0 m/s {
    behavior cruise speed 25 m/s shape cubic duration 4 s max_accel 5 m/s^2
  }
}
"""


@pytest.fixture(scope="module")
def trace():
    result = compile_source(SOURCE, path="road_end_events.addt")
    assert result.ok, render_text(result.diagnostics, result.sources)
    return execute(expand(result.plan).specs[0]).trace


def arrival(track) -> int:
    return int(np.flatnonzero(track.s == 100.0)[0])  # (the first sample held at the end)


def test_road_end_is_the_distance_left_and_0_at_the_end(trace):
    looper = trace.actors["looper"]
    k = arrival(looper)
    assert trace.road_end["looper"][:k] == pytest.approx(100.0 - looper.s[:k])
    assert np.all(trace.road_end["looper"][k:k + 100] == 0.0)


def test_held_end_teleports_once_and_the_actor_stands_where_it_lands(trace):
    looper = trace.actors["looper"]
    k = arrival(looper)  # 60 m at 10 m/s: at 4 s
    assert k * 0.01 == pytest.approx(4.0, abs=0.011)
    assert looper.speed[k] == 10.0 and looper.speed[k + 1] == 0.0  # zeroed the step after it arrived
    # At the end for 1 s (held from sample k): fires on sample k + 100, placed at the next one.
    assert looper.s[k + 100] == 100.0 and looper.s[k + 101] == pytest.approx(20.0)
    # Its cruise had completed: it let go at the end, and the actor stands where it lands
    # (esmini: the speed action ended; nothing sets a speed again).
    assert np.all(looper.speed[k + 1:] == 0.0) and np.all(looper.s[k + 101:] == looper.s[k + 101])
    # `repeat 2`: one run of two, so the step has started and not ended.
    assert np.all(trace.steps["looper.back"][k + 101:] == STEP_STARTED)


def test_teleported_at_once_keeps_its_speed_and_stays_put_in_its_step(trace):
    quick = trace.actors["quick"]
    k = arrival(quick)
    assert quick.s[k] == 100.0 and quick.speed[k] == 10.0
    assert quick.s[k + 1] == 10.0 and quick.speed[k + 1] == 10.0  # placed, not moved on
    assert quick.s[k + 2] == pytest.approx(10.1)
    assert trace.steps["quick.jump"][k + 1] == STEP_ENDED  # (one run: ended at once)


def test_a_cubic_change_over_a_time_is_stretched_to_max_accel(trace):
    ramp = trace.actors["ramp"]
    # 0 -> 25 m/s in 4 s peaks at 1.5 * 25 / 4 = 9.375 m/s^2; at 5 m/s^2 it takes 1.5 * 25 / 5 = 7.5 s.
    assert ramp.speed[375] == pytest.approx(12.5, abs=0.01)
    assert ramp.speed[400] < 14.0 and ramp.speed[750] == pytest.approx(25.0)
    assert np.max(np.diff(ramp.speed)) / 0.01 <= 5.0 + 1e-6
