"""Constraints reject samples (bounded, counted by name), oracles fail runs."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from addt_dsl.compiler import compile_source
from addt_dsl.expr import Binary, Num, Param
from addt_dsl.plan import AssumptionPlan
from addt_dsl.sweep import UnsatisfiableAssumptions, expand, probe_feasibility

TEMPLATE = """
scenario c {{
  duration 10 s
  road r {{ line length 500 m }}
  param gap = 30 m in [10 m, 60 m]
  param v = 15 m/s in [5 m/s, 25 m/s]
  {constraints}
  ego car on r lane -1 at 10 m speed 10 m/s
  agent lead car on r lane -1 at 20 m + gap speed v
  sweep {{
    random 40 seed 2
    max_rejections {cap}
  }}
}}
"""


def compile_plan(constraints: str, cap: int = 1000):
    result = compile_source(TEMPLATE.format(constraints=constraints, cap=cap))
    assert result.ok, result.diagnostics
    return result.plan


def test_every_run_satisfies_the_constraints_and_rejections_are_counted_by_name():
    plan = compile_plan("assume headway: gap > v * 2 s\n  keep v > 8 m/s")
    expansion = expand(plan)
    assert len(expansion.specs) == 40
    for spec in expansion.specs:
        assert spec.params["gap"] > 2 * spec.params["v"] and spec.params["v"] > 8
    assert set(expansion.rejected) <= {"headway", "v > 8 m/s"}
    assert expansion.rejected["headway"] > 0


def test_rejection_is_bounded():
    plan = compile_plan("assume rare: gap > 59.9 m", cap=5)
    with pytest.raises(UnsatisfiableAssumptions, match="rare"):
        expand(plan)


def test_unsatisfiable_is_a_compile_error_with_counts():
    result = compile_source(TEMPLATE.format(constraints="assume never: gap > 100 m", cap=100))
    (diag,) = [d for d in result.diagnostics if d.is_error]
    assert diag.code == "E0501" and any("never" in n and "rejected" in n for n in diag.notes)


@settings(max_examples=30, deadline=None)
@given(st.floats(10.0, 55.0), st.floats(5.0, 22.0))
def test_probe_finds_a_corner_holding_1_5_percent_of_the_space(lo_gap, lo_v):
    """A box in the corner of the sampled space (at least 10 % x 15 % of it): 2000
    candidates miss it with probability below 1e-13, so the probe must find it."""
    plan = compile_plan(f"assume box: gap >= {lo_gap} m and v >= {lo_v} m/s")
    assert probe_feasibility(plan, budget=2000) is None
    far = AssumptionPlan(name="far", text="gap > 59.99 m",
                         expr=Binary(op=">", left=Param(name="gap"), right=Num(value=59.99)))
    no_sampler = plan.sweep.model_copy(update={"sampler": None})
    unsat = plan.model_copy(update={"assumptions": [far], "sweep": no_sampler})
    assert probe_feasibility(unsat, budget=2000) == {"far": 1}  # only the defaults are a candidate
