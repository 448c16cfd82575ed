"""The sweep item `cases` (listed combinations, OpenSCENARIO's ValueSetDistribution): its
rows run together, multiply with the grid, count, print back and are checked like a grid."""

from __future__ import annotations

import pytest

from addt_dsl.compiler import compile_source
from addt_dsl.cost import estimate
from addt_dsl.printer import print_plan
from addt_dsl.sweep import count_runs, expand, probe_feasibility

BASE = """scenario s {{
  duration 5 s
  road r {{ line length 300 m }}
  param v = 10 m/s in [5 m/s, 20 m/s]
  param gap = 30 m in [10 m, 50 m]
  param w = 1 in [0, 3] integer true
  {assume}
  ego car on r lane -1 at 10 m speed v
  agent lead car on r lane -1 at 10 m + gap + w * 1 m speed 5 m/s
  sweep {{
    {sweep}
  }}
}}
"""


def compiled(sweep: str, assume: str = ""):
    return compile_source(BASE.format(sweep=sweep, assume=assume), "s.addt")


def plan_of(sweep: str, assume: str = ""):
    got = compiled(sweep, assume)
    assert got.ok, [(d.code, d.message) for d in got.diagnostics]
    return got.plan


def test_rows_run_together_after_the_grid_axes():
    plan = plan_of("cases v in [5, 20] m/s, gap in [10 m, 50 m]\n    grid w in [0, 3]")
    specs = expand(plan).specs
    assert [(s.params["w"], s.params["v"], s.params["gap"]) for s in specs] == [
        (0, 5, 10), (0, 20, 10 + 40), (3, 5, 10), (3, 20, 50)]
    assert [s.cell for s in specs][1] == {"w": 0, "v": 20, "gap": 50}
    assert count_runs(plan) == 4 and len({s.seed for s in specs}) == 4


def test_two_case_axes_multiply_and_repeat_and_samplers_apply_per_cell():
    plan = plan_of("cases v in [5, 6] m/s\n    cases gap in [10, 20, 30] m\n    repeat 2")
    assert count_runs(plan) == 12 and len(expand(plan).specs) == 12
    sampled = plan_of("cases v in [5, 6] m/s\n    random 3 seed 1")
    specs = expand(sampled).specs
    assert len(specs) == 6 and {s.params["v"] for s in specs} == {5, 6}
    assert len({s.params["gap"] for s in specs}) == 6  # gap is drawn, v is listed
    assert estimate(sampled).runs == 6


def test_assumptions_skip_rows_and_count_them():
    # 10 m > 7.5 m holds, 15 m > 15 m does not, 40 m > 22.5 m holds.
    plan = plan_of("cases v in [5, 10, 15] m/s, gap in [10, 15, 40] m", "assume gap > v * 1.5 s")
    exp = expand(plan)
    assert [(s.params["v"], s.params["gap"]) for s in exp.specs] == [(5, 10), (15, 40)]
    assert sum(exp.rejected.values()) == 1 and count_runs(plan) == 2
    assert probe_feasibility(plan) is None


def test_prints_back_to_the_same_sweep():
    plan = plan_of("grid w in [0, 3]\n    cases v in [5, 20] m/s, gap in [10 m, 50 m]")
    text = print_plan(plan)
    assert "cases v in [5 m/s, 20 m/s], gap in [10 m, 50 m]" in text
    again = compile_source(text, "s.addt")
    assert again.ok and again.plan.sweep == plan.sweep


@pytest.mark.parametrize("sweep, code, said", [
    ("cases v in [5, 20] m/s, gap in [10 m]", "E0204", "different lengths (v: 2, gap: 1)"),
    ("cases v in [5, 30] m/s", "E0301", "outside the range of 'v'"),
    ("cases w in [0, 1.5]", "E0204", "integer parameter"),
    ("cases nobody in [1, 2]", "E0101", "unknown parameter 'nobody'"),
    ("grid v in [5, 6] m/s\n    cases v in [7, 8] m/s", "E0102", "already an axis"),
    ("cases v in [5, 6] m/s, v in [7, 8] m/s", "E0102", "already an axis"),
    ("cases v in [5, 6] s", "E0201", "needs a speed, found a time"),
])
def test_mistakes_are_diagnostics(sweep, code, said):
    got = compiled(sweep)
    errors = [d for d in got.diagnostics if d.is_error]
    assert not got.ok and any(d.code.startswith(code) and said in d.message for d in errors), \
        [(d.code, d.message) for d in errors]
