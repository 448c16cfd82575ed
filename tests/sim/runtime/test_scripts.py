"""Closed loop: an agent's scripted steps start behaviours at the planned times."""

from __future__ import annotations

import numpy as np
import pytest

from addt_dsl.compiler import compile_source
from addt_dsl.runtime.execute import execute
from addt_dsl.sweep import expand
from tests.sim import kit

SOURCE = """
scenario scripted {
  duration 6 s
  road r {
    line length 400 m
    lanes right 2
  }
  ego car on r lane -2 at 10 m speed 10 m/s
  agent lead car ahead of ego 40 m speed 10 m/s {
    behavior cruise speed 10 m/s
    sequence {
      at 1 s behavior lane_change to -1 duration 1 s
      after 1.5 s behavior brake decel 4 m/s^2
      when speed(lead) < 5 m/s then behavior cruise speed 5 m/s
    }
  }
}
"""


@pytest.mark.slow
def test_sequence_runs_in_the_loop():
    result = compile_source(SOURCE)
    assert result.ok, result.diagnostics
    spec = expand(result.plan).specs[0]
    run = execute(spec)
    fired = [(e.detail["behavior"], round(e.time_s, 2)) for e in run.trace.events if e.kind == "trigger"]
    assert fired[:2] == [("lane_change", 1.0), ("brake", 2.5)]
    # Braking at 4 m/s^2 from 10 m/s crosses 5 m/s 1.25 s later (a step after, at the latest).
    assert fired[2][0] == "cruise" and 3.75 <= fired[2][1] <= 3.77
    lead = run.trace.actors["lead"]
    assert abs(lead.lane_offset[-1]) < 0.2 and lead.t[-1] > lead.t[0] + 3.0  # moved one lane left
    assert abs(lead.speed[-1] - 5.0) < 0.3


def test_a_condition_on_objects_reads_what_the_stack_reports_at_its_sample():
    # `objects()` in a condition read 0 at every sample (the condition's snapshot carried no
    # object count), so this step never fired.
    src = """scenario t {
  duration 3 s
  road r {
    line length 400 m
    lanes right 2
  }
  ego car on r lane -1 at 40 m speed 8 m/s {
    stack bev cruise_speed 8 m/s
  }
  agent lead car on r lane -1 at 70 m speed 5 m/s {
    behavior cruise speed 5 m/s
    when objects() >= 1 then behavior cruise speed 12 m/s
  }
}
"""
    tr = kit.run(src)
    k = int(np.argmax(tr.object_count >= 1))
    assert k > 0 and tr.object_count[k - 1] == 0
    assert [e.time_s for e in tr.events if e.kind == "behavior"] == [0.0, tr.time[k]]
