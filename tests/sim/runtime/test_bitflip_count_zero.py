"""`bitflip count 0` is accepted and flips nothing, so a zero-fault baseline sits in the same
grid as the faulty cells (it was refused: `count` started at 1)."""

from __future__ import annotations

from addt_dsl.compiler import compile_source
from addt_dsl.runtime.execute import execute
from addt_dsl.sweep import expand

SOURCE = """scenario flip0 {
  duration 3 s
  step 50 ms
  road street {
    line length 400 m
  }
  param flips = 1 in [0, 4]
  ego car on street lane -1 at 10 m speed 14 m/s {
    stack bev cruise_speed 15 m/s
  }
  faults {
    during [0.5 s, 2 s] bitflip control.accel count flips field exponent
    during [0.5 s, 2 s] bitflip control count flips
  }
  expect {
    no collision
  }
  sweep {
    grid flips in [0, 2]
  }
}
"""


def test_a_zero_count_cell_flips_nothing():
    result = compile_source(SOURCE, path="flip0.addt")
    assert result.ok, result.diagnostics
    specs = expand(result.plan).specs
    assert [s.params["flips"] for s in specs] == [0.0, 2.0]
    zero, two = (execute(s, keep_trace=True) for s in specs)
    assert zero.fault_events == 0 and two.fault_events == 4
    assert [e for e in zero.trace.events if e.kind == "fault"] == []
