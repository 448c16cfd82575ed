"""Formulas on their own (`compiler.formula.parse_formula`) are the DSL's oracle formulas:
same grammar, same checks, and `printer.format_expr` prints them back."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from addt_dsl import expr as E
from addt_dsl import units
from addt_dsl.compiler import compile_source
from addt_dsl.compiler.formula import FormulaError, parse_formula
from addt_dsl.printer import format_expr
from addt_dsl.registry import SIGNALS

gap = E.Signal(name="gap(ego,lead)")


@pytest.mark.parametrize("text, want", [
    ("always gap(ego, lead) > 5 m",
     E.Temporal(op="always", arg=E.Binary(op=">", left=gap, right=E.Num(value=5.0)))),
    ("eventually within 40 s ego.s > 900 m",
     E.Temporal(op="eventually", hi_s=40.0, arg=E.Binary(op=">", left=E.Signal(name="s(ego)"),
                                                         right=E.Num(value=900.0)))),
    ("speed(ego) < 36 km/h until during [1 s, 2 s] latency(planner) < 100 ms",
     E.Until(lo_s=1.0, hi_s=2.0, left=E.Binary(op="<", left=E.Signal(name="speed(ego)"), right=E.Num(value=10.0)),
             right=E.Binary(op="<", left=E.Signal(name="latency(planner)"), right=E.Num(value=0.1)))),
])
def test_parse(text, want):
    assert parse_formula(text) == want


def test_parameters_and_named_signals():
    f = parse_formula("x > gap0 + 1 m", params={"gap0": units.LENGTH}, signals={"x": units.LENGTH})
    assert f == E.Binary(op=">", left=E.Signal(name="x"),
                         right=E.Binary(op="+", left=E.Param(name="gap0"), right=E.Num(value=1.0)))


# What the old hand-written formula parser accepted and the DSL rejects: rejected here too,
# with the compiler's diagnostics (code, column).
@pytest.mark.parametrize("text, code, column", [
    ("speed(ego) > 1 m/s until gap(ego, lead) > 2 m until accel(ego) > 0 m/s^2", "E0001", 47),  # chained until
    ("not always speed(ego) > 1 m/s and gap(ego, lead) > 2 m", "E0001", 12),  # `not always` unparenthesised
    ("-3 < speed(ego)", "E0201", 1),  # a plain number against a speed
])
def test_what_the_dsl_rejects_is_rejected(text, code, column):
    with pytest.raises(FormulaError) as err:
        parse_formula(text)
    assert (err.value.code, err.value.column) == (code, column), str(err.value)
    assert isinstance(err.value, ValueError)
    # ...exactly as in a scenario's expect block.
    source = ("scenario s {\n  duration 10 s\n  road r { line length 100 m }\n  agent lead car on r lane -1 at 50 m\n"
              f"  ego car on r lane -1 at 0 m\n  expect {{\n    {text}\n  }}\n}}\n")
    result = compile_source(source, "s.addt")
    assert code in {d.code for d in result.diagnostics} and not result.ok


@pytest.mark.parametrize("text", ["gap(ego, lead) >", "speed(ego) > 1 m/s )", "speed(ego) # 1", "foo > 1",
                                  "speed(ego) + 1 m/s", "always within 5 m speed(ego) > 0 m/s"])
def test_errors_are_diagnostics(text):
    with pytest.raises(FormulaError) as err:
        parse_formula(text)
    assert err.value.diagnostics and err.value.column >= 1
    assert "<formula>:1:" in str(err.value)


# ---------------------------------------------------------------- print(parse(text)) round trip

ACTORS, NODES = ("ego", "lead"), ("planner", "e2e")


def _signal_texts(dim) -> list[str]:
    out = []
    for cls in SIGNALS.classes():
        if cls.dim != dim or cls.boolean:  # step states are formulas (see STATES)
            continue
        pools = [ACTORS if kind == "actor" else NODES for kind in cls.args]
        if not pools:
            out.append(f"{cls.keyword}()")
        elif len(pools) == 1:
            out += [f"{cls.keyword}({a})" for a in pools[0]]
        else:
            out += [f"{cls.keyword}({a}, {b})" for a in pools[0] for b in pools[1] if a != b]
    return out


DIMS = [d for d in (units.LENGTH, units.TIME, units.SPEED, units.ACCELERATION, units.DIMENSIONLESS)
        if _signal_texts(d)]
numbers = st.floats(-1e4, 1e4, allow_nan=False).map(repr)


def values(dim, depth: int = 1):
    unit = units.CANONICAL_UNIT.get(dim, "")
    quantity = numbers.map(lambda n: f"{n} {unit}".strip())
    leaf = st.one_of(quantity, st.sampled_from(_signal_texts(dim)))
    if depth == 0:
        return leaf
    sub = values(dim, depth - 1)
    return st.one_of(
        leaf,
        st.builds(lambda a, op, b: f"({a}) {op} ({b})", sub, st.sampled_from("+-"), sub),
        st.builds(lambda a, b: f"({a}) * {b}", sub, numbers),
        st.builds(lambda fn, a, b: f"{fn}({a}, {b})", st.sampled_from(["min", "max"]), sub, sub),
        sub.map(lambda a: f"abs({a})"),
        sub.map(lambda a: f"-({a})"),
    )


comparisons = st.sampled_from(DIMS).flatmap(
    lambda d: st.builds(lambda a, op, b: f"{a} {op} {b}", values(d), st.sampled_from(E.COMPARE_OPS), values(d)))
seconds = st.floats(0, 10, allow_nan=False).map(lambda t: f"{t!r} s")
windows = st.one_of(st.just(""), seconds.map(lambda t: f" within {t}"), seconds.map(lambda t: f" after {t}"),
                    st.tuples(st.floats(0, 5), st.floats(0, 5)).map(
                        lambda w: f" during [{w[0]!r} s, {w[0] + w[1]!r} s]"))


STATES = st.sampled_from([f"{fn}({a}.{step})" for fn in ("started", "ended") for a in ACTORS
                          for step in ("brake_hard", "swerve")])


def formulas(depth: int = 3):
    """Formula text, every operand in parentheses: the printer decides which ones it needs."""
    leaf = st.one_of(comparisons, st.sampled_from(["true", "false"]), STATES)
    if depth == 0:
        return leaf
    sub = formulas(depth - 1)
    return st.one_of(
        leaf,
        sub.map(lambda a: f"not ({a})"),
        st.builds(lambda a, op, b: f"({a}) {op} ({b})", sub, st.sampled_from(["and", "or", "implies"]), sub),
        st.builds(lambda op, w, a: f"{op}{w} ({a})", st.sampled_from(["always", "eventually"]), windows, sub),
        st.builds(lambda a, w, b: f"({a}) until{w} ({b})", sub, windows, sub),
    )


@settings(max_examples=200, deadline=None)
@given(formulas())
def test_print_parse_round_trip(text):
    """print(parse(text)) is the normalised text: it parses to the same tree and prints
    as itself."""
    tree = parse_formula(text)
    normalised = format_expr(tree)
    assert parse_formula(normalised) == tree, normalised
    assert format_expr(parse_formula(normalised)) == normalised
