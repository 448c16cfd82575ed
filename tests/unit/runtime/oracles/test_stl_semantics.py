"""Worked examples of each decision in the semantics, and the error cases."""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from tests.unit.runtime.oracles.stl_testkit import parse as parse_formula
from tests.unit.runtime.oracles.stl_testkit import robustness

from addt_dsl.expr import Binary, Num, Param, Signal, Temporal, Unary
from addt_dsl.runtime.oracles import (
    FormulaTypeError,
    UnknownSignalError,
    UnsubstitutedParameterError,
    evaluate,
    first_violation_time,
    robustness_over_time,
    robustness_at_0,
    samples,
    satisfied,
)

INF = math.inf


def rho(text, period=1.0, **sig):
    return evaluate(parse_formula(text), {k: np.asarray(v, float) for k, v in sig.items()}, period)


def sat(text, period=1.0, **sig):
    return satisfied(parse_formula(text), {k: np.asarray(v, float) for k, v in sig.items()}, period)


@pytest.mark.parametrize("text, want", [
    ("x > 1", 2.0), ("x >= 1", 2.0), ("x < 1", -2.0), ("x <= 1", -2.0),
    ("x == 1", -2.0), ("x != 1", 2.0), ("1 < x", 2.0),
])
def test_comparison_margins(text, want):
    assert rho(text, x=[3.0])[0] == want


def test_connectives():
    sig = dict(x=[3.0], y=[-1.0])
    assert rho("x > 0 and y > 0", **sig)[0] == -1.0
    assert rho("x > 0 or y > 0", **sig)[0] == 3.0
    assert rho("not x > 0", **sig)[0] == -3.0
    assert rho("x > 0 implies y > 0", **sig)[0] == -1.0   # max(-3, -1)
    assert rho("y > 0 implies x > 5", **sig)[0] == 1.0    # max(1, -2)


def test_arithmetic_and_calls():
    sig = dict(x=[3.0, -4.0], y=[4.0, 3.0])
    value = parse_formula("sqrt(x * x + y * y) > 0").left  # a value expression: the formula's left side
    np.testing.assert_array_equal(evaluate(value, {k: np.array(v) for k, v in sig.items()}, 1.0), [5.0, 5.0])
    np.testing.assert_array_equal(rho("abs(x) - min(x, y) / 2 + max(x, y, 0) > -x", **sig),
                                  [3 - 1.5 + 4 + 3, 4 + 2 + 3 - 4])


def test_bounded_windows_are_cut_off_at_the_trace_end():
    x = [1.0, 2.0, 3.0, 4.0, 5.0]
    # always during [1, 2]: samples 1..2, 2..3, 3..4, then 4..4 (cut), then empty (+inf)
    np.testing.assert_array_equal(rho("always during [1 s, 2 s] x > 0", x=x), [2, 3, 4, 5, INF])
    np.testing.assert_array_equal(rho("eventually during [1 s, 2 s] x > 0", x=x), [3, 4, 5, 5, -INF])
    np.testing.assert_array_equal(rho("always x > 0", x=x), [1, 2, 3, 4, 5])
    np.testing.assert_array_equal(rho("eventually after 3 s x > 0", x=x), [5, 5, -INF, -INF, -INF])


def test_until():
    x = [1.0, 2.0, -1.0, 3.0]
    y = [-5.0, -1.0, 4.0, 0.5]
    # rho[t] = max_{t' in window} min(y[t'], min x[t..t'-1])
    np.testing.assert_array_equal(rho("x > 0 until y > 0", x=x, y=y), [1, 2, 4, 0.5])
    np.testing.assert_array_equal(rho("x > 0 until within 1 s y > 0", x=x, y=y), [-1, 2, 4, 0.5])
    np.testing.assert_array_equal(rho("x > 0 until after 1 s y > 0", x=x, y=y), [1, 2, -1, -INF])


def test_period_scales_windows():
    x = [0.0] * 10 + [1.0]
    assert robustness("eventually within 1 s x > 0", {"x": x}, 0.1) == 1.0
    assert robustness("eventually within 900 ms x > 0", {"x": x}, 0.1) == 0.0
    assert robustness("eventually within 0.95 s x > 0", {"x": x}, 0.1) == 1.0  # ties round up


def test_sample_rounding():
    assert samples(0.3, 0.1) == 3
    assert samples(0.05, 0.1) == 1
    assert samples(0.149, 0.1) == 1


@given(st.integers(0, 10**6), st.sampled_from([1.0, 0.1, 0.05, 0.02, 0.01, 0.001, 1 / 60]))
def test_whole_sample_windows_convert_exactly(k, period):
    assert samples(k * period, period) == k


@pytest.mark.parametrize("text, holds", [
    ("x >= 0", True), ("x > 0", False), ("x <= 0", True), ("x < 0", False),
    ("x == 0", True), ("x != 0", False), ("not x > 0", True), ("not x >= 0", False),
    ("always x >= 0", True), ("x > 0 or x >= 0", True), ("x > 0 implies x > 1", True),
])
def test_verdict_at_zero_robustness_follows_the_boolean_semantics(text, holds):
    assert rho(text, x=[0.0])[0] == 0.0
    assert sat(text, x=[0.0]) is holds


def test_nan_is_the_worst_case_even_under_negation():
    assert rho("x > 0", x=[math.nan])[0] == -INF
    assert rho("not x > 0", x=[math.nan])[0] == -INF
    assert rho("x != 0", x=[math.nan])[0] == -INF
    assert rho("not (x > 0 and y > 0)", x=[math.nan], y=[1.0])[0] == -1.0  # as if x > 0 held
    assert rho("x > 0 implies y > 0", x=[math.nan], y=[-1.0])[0] == -1.0
    # ...but a NaN doesn't sink a formula that holds whatever the unknown value is
    assert rho("x > 0 implies y > 0", x=[math.nan], y=[2.0])[0] == 2.0
    assert rho("x > 0 or y > 0", x=[math.nan], y=[2.0])[0] == 2.0
    assert not sat("always x < 10", x=[1.0, math.nan, 2.0])


def test_infinities_and_arithmetic_nan():
    assert rho("x > 0", x=[INF])[0] == INF
    assert rho("x < y", x=[INF], y=[INF])[0] == -INF   # inf - inf: unknown (a non-finite literal is E0204)
    assert rho("x / y > 0", x=[1.0], y=[0.0])[0] == INF
    assert rho("x / y > 0", x=[0.0], y=[0.0])[0] == -INF  # 0/0
    assert rho("not sqrt(x) > 0", x=[-1.0])[0] == -INF


def test_first_violation_time():
    f = parse_formula("always x > 0")
    sig = {"x": np.array([1.0, 1.0, 1.0, -1.0, 1.0, -2.0])}
    assert first_violation_time(f, sig, 0.1) == pytest.approx(0.3)
    assert first_violation_time(parse_formula("always during [0.4 s, 1 s] x > 0"), sig, 0.1) == pytest.approx(0.5)
    assert first_violation_time(parse_formula("always x > -5"), sig, 0.1) is None
    assert first_violation_time(parse_formula("always x >= 1"), sig, 0.1) == pytest.approx(0.3)
    both = parse_formula("always x > -1.5 and (always within 0.2 s x < 1)")
    assert first_violation_time(both, sig, 0.1) == pytest.approx(0.0)
    assert first_violation_time(parse_formula("(always x > -1.5) and (always x > 0)"), sig, 0.1) == pytest.approx(0.3)
    # `eventually`: certain only when its window closes (or the run ends), never "at 0 s".
    assert first_violation_time(parse_formula("eventually x > 5"), sig, 0.1) == pytest.approx(0.5)
    assert first_violation_time(parse_formula("eventually within 0.2 s x > 5"), sig, 0.1) == pytest.approx(0.2)
    assert first_violation_time(parse_formula("eventually within 3 s x > 5"), sig, 0.1) == pytest.approx(0.5)
    assert first_violation_time(parse_formula("eventually within 0.2 s x >= 1"), sig, 0.1) is None
    either = parse_formula("(always x > 0) or (eventually within 0.4 s x > 5)")
    assert first_violation_time(either, sig, 0.1) == pytest.approx(0.4)  # the later of the two
    assert first_violation_time(parse_formula("x > 5"), sig, 0.1) == 0.0
    assert first_violation_time(parse_formula("not (always x > -5)"), sig, 0.1) is None  # no instant to name
    zero = {"x": np.array([1.0, 0.0, 1.0])}  # a tie counts as a violation of a strict bound
    assert first_violation_time(f, zero, 0.5) == 0.5


def test_robustness_over_time_is_the_margin_of_the_body():
    sig = {"x": np.array([1.0, 1.0, -1.0, 2.0])}
    np.testing.assert_allclose(robustness_over_time(parse_formula("always x > 0"), sig, 0.1), [1, 1, -1, 2])
    np.testing.assert_allclose(robustness_over_time(parse_formula("eventually x > 3"), sig, 0.1), [-2, -2, -4, -1])
    # Not temporal at the top: the formula judged at each sample.
    np.testing.assert_allclose(robustness_over_time(parse_formula("x > 0 and x < 1.5"), sig, 0.1),
                               [0.5, 0.5, -1, -0.5])


def test_evaluate_value_expression_and_no_aliasing():
    x = np.array([1.0, 2.0])
    out = evaluate(Signal(name="x"), {"x": x}, 1.0)
    out[0] = 99.0
    assert x[0] == 1.0


def test_constant_formula_takes_the_trace_length():
    expr = Binary(op=">", left=Num(value=2.0), right=Num(value=1.0))
    np.testing.assert_array_equal(evaluate(expr, {"x": np.zeros(3)}, 1.0), [1.0, 1.0, 1.0])
    assert robustness_at_0(expr, {}, 1.0) == 1.0


def test_errors():
    with pytest.raises(UnknownSignalError, match="unknown signal 'ttc\\(ego,lead\\)'") as err:
        robustness("ttc(ego, lead) > 1 s", {"x": [1.0]}, 0.1)
    assert isinstance(err.value, KeyError)
    with pytest.raises(UnsubstitutedParameterError, match="gap"):
        evaluate(Binary(op=">", left=Signal(name="x"), right=Param(name="gap")), {"x": np.ones(2)}, 1.0)
    # Trees the compiler would reject (a value where a formula belongs, or the reverse),
    # built by hand: the evaluator still refuses them.
    x, one = Signal(name="x"), Num(value=1.0)
    x_pos = Binary(op=">", left=x, right=Num(value=0.0))
    sig = {"x": [1.0], "y": [1.0]}
    with pytest.raises(FormulaTypeError, match="operand of 'and' must be a formula"):
        robustness_at_0(Binary(op="and", left=x, right=Binary(op=">", left=Signal(name="y"), right=one)), sig, 1.0)
    with pytest.raises(FormulaTypeError, match="must be a value"):
        robustness_at_0(Binary(op=">", left=Binary(op="+", left=x_pos, right=one), right=Num(value=0.0)), sig, 1.0)
    with pytest.raises(FormulaTypeError, match="expected a formula"):
        robustness_at_0(Binary(op="+", left=x, right=one), sig, 1.0)
    with pytest.raises(FormulaTypeError):
        robustness_at_0(Unary(op="not", arg=x), sig, 1.0)
    with pytest.raises(ValueError, match="differ in length"):
        robustness("x > y", {"x": [1.0], "y": [1.0, 2.0]}, 1.0)
    with pytest.raises(ValueError, match="period"):
        robustness("x > 0", {"x": [1.0]}, 0.0)
    with pytest.raises(ValueError, match="empty trace"):
        robustness("x > 0", {"x": []}, 1.0)
    with pytest.raises(ValueError, match="window"):
        evaluate(Temporal(op="always", lo_s=-1.0, hi_s=2.0,
                          arg=Binary(op=">", left=Signal(name="x"), right=Num(value=0.0))),
                 {"x": np.ones(2)}, 1.0)
