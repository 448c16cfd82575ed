"""Oracle windows over parameters (`always during [0 s, t_end] ...`): compiled to bounds
that each run resolves, checked at compile time for every run whose values the sweep
fixes (grid, cases, defaults), over the values a sampler can draw where it draws them
(the ranges narrowed by the constraints); printed back to the
same plan; evaluated exactly like the same literal window."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from addt_dsl import expr as E
from addt_dsl import units
from addt_dsl.compiler import compile_source
from addt_dsl.compiler.formula import parse_formula
from addt_dsl.printer import format_expr, print_plan
from addt_dsl.runtime.bound import WindowError, bind
from addt_dsl.runtime.oracles import robustness_over_time
from addt_dsl.sweep import expand, make_spec
from tests.unit.runtime.oracles.stl_testkit import PERIODS, SIGNALS, formulas, traces

SOURCE = """scenario windows {{
  duration 10 s
  road r {{ line length 400 m }}
  param t_end = 4 s
  param t0 = 1 s
{params}
  ego car on r lane -1 at 20 m speed 10 m/s
  agent lead car on r lane -1 at 60 m speed 10 m/s {{
    behavior cruise speed 10 m/s
  }}
  expect {{
    {oracle}
  }}
{sweep}
}}
"""


def _compile(oracle: str, sweep: str = "", params: str = ""):
    return compile_source(SOURCE.format(oracle=oracle, sweep=sweep, params=params), path="w.addt")


def _errors(oracle: str, sweep: str = "", params: str = "") -> list[tuple[str, str, tuple[str, ...]]]:
    result = _compile(oracle, sweep, params)
    return [(d.code, d.message, tuple(d.notes)) for d in result.diagnostics if d.severity == "error"]


def _formula(result, name: str = "w"):
    return next(o.formula for o in result.plan.oracles if o.name == name)


def test_a_parameter_window_compiles_to_its_expression():
    f = _formula(_compile("w: always during [t0, t_end + 1 s] gap(ego, lead) > 5 m"))
    assert f.lo_s == E.Param(name="t0")
    assert f.hi_s == E.Binary(op="+", left=E.Param(name="t_end"), right=E.Num(value=1.0))
    until = _formula(_compile("w: speed(ego) > 1 m/s until within t_end speed(lead) > 1 m/s"))
    assert (until.lo_s, until.hi_s) == (0.0, E.Param(name="t_end"))


def test_a_constant_window_is_still_a_number():
    """Constant bounds fold to the float they always were (plans, run keys unchanged)."""
    f = _formula(_compile("w: always during [250 ms, 2 * 5 s] gap(ego, lead) > 5 m"))
    assert type(f.lo_s) is float and type(f.hi_s) is float
    assert (f.lo_s, f.hi_s) == (0.25, 10.0)
    assert '"lo_s":0.25,"hi_s":10.0' in f.model_dump_json()


@pytest.mark.parametrize("oracle, sweep, code, note", [
    # A bound negative in one cell of the grid (not at the default): the cell is named.
    ("w: always within t_end - 3 s gap(ego, lead) > 5 m", "sweep { grid t_end in [4, 2] s }", "E0301",
     "with t_end = 2 s (a run of the sweep)"),
    ("w: always during [t0, t_end] gap(ego, lead) > 5 m", "sweep { grid t0 in [1, 5] s }", "E0303",
     "with t0 = 5 s, t_end = 4 s (a run of the sweep)"),
    ("w: always during [t0, t_end] gap(ego, lead) > 5 m",
     "sweep { cases t0 in [1, 3] s, t_end in [2, 2.5] s }", "E0303",
     "with t0 = 3 s, t_end = 2.5 s (a run of the sweep)"),
    ("w: always within t_end + 1 s gap(ego, lead) > 5 m", "sweep { grid t_end in [4, 9.5] s }", "E0302",
     "with t_end = 9.5 s (a run of the sweep)"),
    ("w: speed(ego) > 1 m/s until during [t0, 2 s] speed(lead) > 1 m/s", "sweep { grid t0 in [1, 3] s }",
     "E0303", "with t0 = 3 s (a run of the sweep)"),
    ("reach goal within t_end - 5 s", "", "E0301", "with t_end = 4 s (a run of the sweep)"),
])
def test_a_bad_window_in_some_run_of_the_sweep_is_a_compile_error(oracle, sweep, code, note):
    result = compile_source(_goal(SOURCE.format(oracle=oracle, sweep=sweep, params="")), path="w.addt")
    errors = [(d.code, d.notes) for d in result.diagnostics if d.severity == "error"]
    assert len(errors) == 1, errors
    assert errors[0][0] == code
    assert note in errors[0][1]


def _goal(source: str) -> str:
    """The scenario with a goal on the ego (for `reach goal`)."""
    return source.replace("speed 10 m/s\n  agent", "speed 10 m/s goal 300 m\n  agent", 1)


def test_the_same_sweep_without_the_bad_cell_compiles():
    assert _errors("w: always within t_end - 3 s gap(ego, lead) > 5 m", "sweep { grid t_end in [4, 3] s }") == []
    # An assumption that rejects the bad cell: that cell runs nothing, so nothing to refuse.
    assert _errors("w: always during [t0, t_end] gap(ego, lead) > 5 m", "sweep { grid t0 in [1, 5] s }",
                   "  assume t0 <= t_end") == []


def test_constant_windows_keep_their_diagnostics():
    assert [c for c, _, _ in _errors("w: always during [5 s, 2 s] gap(ego, lead) > 5 m")] == ["E0303"]
    assert [c for c, _, _ in _errors("w: always within 12 s gap(ego, lead) > 5 m")] == ["E0302"]
    assert [c for c, _, _ in _errors("w: always during [-1 s, 2 s] gap(ego, lead) > 5 m")] == ["E0301"]
    # `until` had no check of an inverted window: the run crashed in the evaluator.
    assert [c for c, _, _ in _errors("w: speed(ego) > 1 m/s until during [5 s, 2 s] speed(lead) > 1 m/s")] \
        == ["E0303"]
    # A window bound is a time.
    assert [c for c, _, _ in _errors("w: always within t_end * 1 m/s gap(ego, lead) > 5 m")] == ["E0201"]


SAMPLED = "  param t_s = 3 s in [1 s, 6 s]"


def test_a_sampled_parameter_is_checked_over_the_values_its_runs_can_draw():
    """Where a sampler draws the bound, a window that some drawable value makes invalid is
    refused at compile time (as a fault's time over the same parameter is); the constraints
    narrow what can be drawn, so an `assume` that excludes the bad values lets it compile."""
    assert _errors("w: always during [t_s, 4 s] gap(ego, lead) > 5 m", "sweep { random 4 }", SAMPLED) == [
        ("E0303", "the window can end before it starts",
         ("over the ranges of t_s its end can come before its start",
          "narrow the parameter range, or add an `assume` that excludes those values"))]
    assert [c for c, _, _ in _errors("w: always within t_s + 5 s gap(ego, lead) > 5 m", "sweep { random 4 }",
                                     SAMPLED)] == ["E0302"]
    result = _compile("w: always during [t_s, 4 s] gap(ego, lead) > 5 m", "sweep { random 4 }",
                      SAMPLED + "\n  assume t_s <= 4 s")
    assert result.plan is not None, result.diagnostics
    for spec in expand(result.plan).specs:  # every run draws a value the window takes
        assert 1.0 <= bind(spec).oracles[0].formula.lo_s <= 4.0
    # A constraint that orders the bounds excludes an inverted window; one that bounds
    # only one side does not.
    two = SAMPLED + "\n  param t_e = 5 s in [2 s, 8 s]"
    assert _errors("w: always during [t_s, t_e] gap(ego, lead) > 5 m", "sweep { random 4 }",
                   two + "\n  assume t_s < t_e") == []
    assert [c for c, _, _ in _errors("w: always during [t_s, t_e] gap(ego, lead) > 5 m", "sweep { random 4 }",
                                     two + "\n  assume t_e > 3 s")] == ["E0303"]


def test_the_run_time_check_names_the_oracle_the_window_and_the_values():
    # The check as a run binds stays the guard: a RunSpec made by hand with a value the
    # constraints exclude (make_spec does not check them) fails with a clear error, not in
    # the evaluator.
    result = _compile("w: always during [t_s, 4 s] gap(ego, lead) > 5 m", "sweep { random 4 }",
                      SAMPLED + "\n  assume t_s <= 4 s")
    bad = make_spec(result.plan, {**result.plan.nominal_params(), "t_s": 5.5}, 0)
    with pytest.raises(WindowError) as info:
        bind(bad)
    assert str(info.value) == ("oracle 'w': the window ends before it starts: its window is [5.5 s, 4 s] "
                               "with t_s = 5.5 s")


def test_the_runs_of_a_sweep_resolve_their_windows():
    result = _compile("w: always during [0 s, t_end] gap(ego, lead) > 5 m", "sweep { grid t_end in [4, 8] s }")
    bound = [bind(spec).oracles[0].formula for spec in expand(result.plan).specs]
    assert [(f.lo_s, f.hi_s) for f in bound] == [(0.0, 4.0), (0.0, 8.0)]
    assert "t_end" not in result.plan.fault_only_params()


@pytest.mark.parametrize("oracle", [
    "w: always during [0 s, t_end] gap(ego, lead) > 5 m",
    "w: eventually within t_end + 1 s speed(ego) > 1 m/s",
    "w: always within (t_end) (-speed(ego) < 0 m/s)",
    "w: always after (t0) (speed(ego) > 1 m/s)",
    "w: eventually during [t0, min(t_end, 3 s)] (speed(ego) > 1 m/s or speed(lead) < 0.5 m/s)",
    "w: speed(ego) > 1 m/s until during [t_end / 2, t_end] speed(ego) > 2 m/s",
    "w: speed(ego) > 1 m/s until within (2 * t0) (-speed(ego) < -2 m/s)",
    "w: always during [t0, 2 s] eventually within (t_end) (speed(ego) > 1 m/s)",
])
def test_print_round_trip(oracle):
    """.addt -> plan -> .addt -> the same plan, with the oracle printed from its tree (not
    the source text): a bound over parameters followed by a parenthesis is parenthesised,
    or `within t_end (x)` would read as a call."""
    plan = _compile(oracle, "sweep { grid t_end in [4, 5] s }").plan
    assert plan is not None
    plan = plan.model_copy(update={"oracles": [o.model_copy(update={"text": ""}) for o in plan.oracles]})
    text = print_plan(plan)
    again = compile_source(text, path="w.addt")
    assert again.plan is not None, (text, again.diagnostics)
    assert [o.formula for o in again.plan.oracles] == [o.formula for o in plan.oracles], text


def test_reach_goal_within_a_parameter_round_trips():
    src = _goal(SOURCE.format(oracle="reach goal within t_end + 5 s", sweep="", params=""))
    plan = compile_source(src, path="w.addt").plan
    assert plan is not None
    f = plan.oracles[0].formula
    assert f.hi_s == E.Binary(op="+", left=E.Param(name="t_end"), right=E.Num(value=5.0))
    text = print_plan(plan)
    assert "reach goal within t_end + 5 s" in text
    assert compile_source(text, path="w.addt").plan.oracles == plan.oracles


# ---------------------------------------------------------------- property

TIME = {"a": units.TIME, "d": units.TIME}
bounds = st.tuples(st.integers(0, 40), st.integers(0, 40), st.sampled_from(["s", "ms"]))


def _literal(n: int, unit: str) -> tuple[str, float]:
    """A decimal literal in `unit` and its value in SI, as the compiler reads a parameter's default."""
    value = n / 10 if unit == "s" else n * 100
    text = f"{value!r} {unit}"
    return text, units.to_si(value, unit)[0]


@settings(max_examples=150, deadline=None)
@given(period=st.sampled_from(PERIODS), data=st.data(), shape=st.sampled_from(["within", "after", "during", "until"]),
       op=st.sampled_from(["always", "eventually"]), b=bounds)
def test_a_parameter_window_evaluates_exactly_like_the_literal_window(period, data, shape, op, b):
    (a_text, a), (d_text, d) = _literal(b[0], b[2]), _literal(b[1], b[2])
    window = {"within": ("within a", f"within {a_text}"), "after": ("after a", f"after {a_text}"),
              "during": ("during [a, a + d]", f"during [{a_text}, {a_text} + {d_text}]"),
              "until": ("during [a, a + d]", f"during [{a_text}, {a_text} + {d_text}]")}[shape]
    if shape == "until":
        texts = [f"x > 0 until {w} y > 0" for w in window]
    else:
        texts = [f"{op} {w} x > 0" for w in window]
    with_params = parse_formula(texts[0], params=TIME, signals={s: units.DIMENSIONLESS for s in SIGNALS})
    literal = parse_formula(texts[1], signals={s: units.DIMENSIONLESS for s in SIGNALS})
    # Any operand: the window is what differs.
    if shape == "until":
        left, right = data.draw(formulas(period, max_leaves=4)), data.draw(formulas(period, max_leaves=4))
        with_params = with_params.model_copy(update={"left": left, "right": right})
        literal = literal.model_copy(update={"left": left, "right": right})
    else:
        arg = data.draw(formulas(period, max_leaves=4))
        with_params = with_params.model_copy(update={"arg": arg})
        literal = literal.model_copy(update={"arg": arg})
    resolved = E.substitute_params(with_params, {"a": a, "d": d})
    assert resolved == literal
    trace = data.draw(traces())
    got = robustness_over_time(resolved, trace, period)
    want = robustness_over_time(literal, trace, period)
    assert np.array_equal(got, want, equal_nan=True)


def test_a_parameter_window_prints_and_parses_back():
    f = parse_formula("always during [a, a + d] eventually within (d) (-speed(ego) < 0 m/s)", params=TIME)
    text = format_expr(f, param_dims=TIME)
    assert text == "always during [a, a + d] eventually within (d) (-speed(ego) < 0 m/s)"
    assert parse_formula(text, params=TIME) == f


def test_a_bound_read_as_a_call_gets_a_hint():
    result = _compile("always within t_end (speed(ego) > 1 m/s)")
    (error,) = [d for d in result.diagnostics if d.severity == "error"]
    assert error.code == "E0001"
    assert "`t_end (` reads as a call: put a window bound over parameters in parentheses, " \
           "`within (t_end) (...)`" in error.notes
    assert [d.code for d in _compile("always within (t_end) (speed(ego) > 1 m/s)").diagnostics
            if d.severity == "error"] == []
