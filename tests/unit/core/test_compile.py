"""The walking skeleton's compiler slice: plan in SI, diagnostics with spans, all errors."""

from addt_dsl.compiler import compile_source
from addt_dsl.diagnostics import render_text
from addt_dsl.expr import Num

GOOD = """
scenario s {
  duration 10 s
  road r {
    line length 300 m
    lanes right 2 width 3.5 m
  }
  param v = 36 km/h in [18 km/h, 72 km/h]
  ego car on r lane -2 at 10 m speed v
  expect {
    no collision
  }
}
"""


def test_plan_is_in_si_units():
    result = compile_source(GOOD, "good.addt")
    assert result.ok, render_text(result.diagnostics, result.sources)
    plan = result.plan
    assert plan.duration_s == 10.0
    (param,) = plan.params
    assert (param.default, param.low, param.high) == (10.0, 5.0, 20.0)
    assert plan.roads[0].segments[0].length_m == 300.0
    assert plan.ego.s == Num(value=10.0)
    assert [o.name for o in plan.oracles] == ["no_collision"]


def test_dimension_mismatch_has_location_and_caret():
    src = GOOD.replace("speed v", "speed 10 m")
    result = compile_source(src, "bad.addt")
    assert not result.ok
    (d,) = [d for d in result.diagnostics if d.is_error]
    assert d.code == "E0201"
    assert (d.span.file, d.span.line) == ("bad.addt", 9)
    text = render_text(result.diagnostics, result.sources)
    assert "bad.addt:9:" in text and "^" in text and "Traceback" not in text


def test_all_errors_are_collected():
    src = GOOD.replace("speed v", "speed 10 m").replace("no collision", "always ttc(ego, nobody) > 1 s")
    src = src.replace("line length 300 m", "wiggle length 300 m")
    result = compile_source(src, "bad.addt")
    codes = sorted(d.code for d in result.diagnostics if d.is_error)
    assert codes == ["E0101", "E0106", "E0201"]


def test_syntax_error_is_a_diagnostic():
    result = compile_source("scenario s {\n  duration = 10 s\n}\n", "syn.addt")
    assert not result.ok
    d = result.diagnostics[0]
    assert d.code == "E0001" and d.span.line == 2
    assert any("without '='" in n for n in d.notes)


def test_unused_parameter_warns():
    src = GOOD.replace("speed v", "speed 10 m/s")
    result = compile_source(src, "w.addt")
    assert result.ok
    assert [d.code for d in result.diagnostics] == ["W0001"]


def test_fault_target_checked_against_stack_registry():
    src = GOOD.replace("  expect {", "  faults {\n    stuck planner.nonexistent value 1\n  }\n  expect {")
    result = compile_source(src, "f.addt")
    assert [d.code for d in result.diagnostics if d.is_error] == ["E0107"]


def test_fault_window_must_lie_inside_duration():
    src = GOOD.replace("  expect {", "  faults {\n    during [5 s, 12 s] drop lidar rate 50 %\n  }\n  expect {")
    result = compile_source(src, "f.addt")
    assert [d.code for d in result.diagnostics if d.is_error] == ["E0302"]
