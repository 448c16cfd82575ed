"""Property tests: the fast evaluator against the by-the-book reference, and the
algebraic laws of the semantics."""

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from tests.unit.runtime.oracles.stl_testkit import PERIODS, formulas, reference_signal, traces, windows

from addt_dsl.expr import Binary, Num, Temporal, Unary, Until
from addt_dsl.runtime.oracles import boolean_semantics, evaluate, verdicts

periods = st.sampled_from(PERIODS)


@st.composite
def cases(draw, arith=True, nan=False):
    period = draw(periods)
    return draw(formulas(period, arith=arith)), draw(traces(nan=nan)), period


@settings(max_examples=300, deadline=None)
@given(cases())
def test_matches_reference_at_every_sample(case):
    expr, sig, period = case
    np.testing.assert_array_equal(evaluate(expr, sig, period), reference_signal(expr, sig, period))


@settings(max_examples=200, deadline=None)
@given(cases(nan=True))
def test_matches_reference_with_nan(case):
    expr, sig, period = case
    np.testing.assert_array_equal(evaluate(expr, sig, period), reference_signal(expr, sig, period))


@settings(max_examples=300, deadline=None)
@given(cases(nan=True))
def test_boolean_semantics_matches_reference(case):
    expr, sig, period = case
    want = reference_signal(expr, sig, period, boolean=True) > 0
    np.testing.assert_array_equal(boolean_semantics(expr, sig, period), want)


@settings(max_examples=300, deadline=None)
@given(cases(nan=True))
def test_robustness_sign_never_disagrees_with_boolean_verdict(case):
    expr, sig, period = case
    rho = evaluate(expr, sig, period)
    truth = boolean_semantics(expr, sig, period)
    assert not np.any((rho > 0) & ~truth), "rho > 0 but the formula is false"
    assert not np.any((rho < 0) & truth), "rho < 0 but the formula is true"
    np.testing.assert_array_equal(verdicts(expr, sig, period), truth)


@settings(max_examples=200, deadline=None)
@given(cases(nan=True))
def test_double_negation(case):
    expr, sig, period = case
    nn = Unary(op="not", arg=Unary(op="not", arg=expr))
    np.testing.assert_array_equal(evaluate(nn, sig, period), evaluate(expr, sig, period))


@settings(max_examples=200, deadline=None)
@given(st.data())
def test_always_is_not_eventually_not(data):
    period = data.draw(periods)
    expr, sig = data.draw(formulas(period)), data.draw(traces(nan=True))
    lo, hi = data.draw(windows(period))
    always = Temporal(op="always", lo_s=lo, hi_s=hi, arg=expr)
    dual = Unary(op="not", arg=Temporal(op="eventually", lo_s=lo, hi_s=hi,
                                          arg=Unary(op="not", arg=expr)))
    np.testing.assert_array_equal(evaluate(always, sig, period), evaluate(dual, sig, period))
    np.testing.assert_array_equal(verdicts(always, sig, period), verdicts(dual, sig, period))


@settings(max_examples=200, deadline=None)
@given(st.data())
def test_eventually_is_true_until(data):
    period = data.draw(periods)
    expr, sig = data.draw(formulas(period)), data.draw(traces())
    lo, hi = data.draw(windows(period))
    true = _true()
    ev = Temporal(op="eventually", lo_s=lo, hi_s=hi, arg=expr)
    un = Until(lo_s=lo, hi_s=hi, left=true, right=expr)
    np.testing.assert_array_equal(evaluate(ev, sig, period), evaluate(un, sig, period))


def _true():
    return Binary(op="<", left=Num(value=0.0), right=Num(value=math.inf))


@settings(max_examples=200, deadline=None)
@given(st.data())
def test_wider_window_is_monotone(data):
    """Widening a window can only lower `always` and raise `eventually`."""
    period = data.draw(periods)
    expr, sig = data.draw(formulas(period)), data.draw(traces())
    lo = data.draw(st.integers(0, 4))
    hi = data.draw(st.integers(lo, lo + 6))
    grow_lo = data.draw(st.integers(0, lo))
    grow_hi = data.draw(st.one_of(st.none(), st.integers(hi, hi + 6)))
    def rho(op, a, b):
        return evaluate(Temporal(op=op, lo_s=a * period, hi_s=None if b is None else b * period,
                                 arg=expr), sig, period)
    assert np.all(rho("always", grow_lo, grow_hi) <= rho("always", lo, hi))
    assert np.all(rho("eventually", grow_lo, grow_hi) >= rho("eventually", lo, hi))


@settings(max_examples=200, deadline=None)
@given(st.data())
def test_nan_never_helps(data):
    """Replacing a NaN sample by any number can only raise robustness: a NaN is
    treated as the worst case wherever it appears, negated or not."""
    period = data.draw(periods)
    expr, sig = data.draw(formulas(period, arith=True)), data.draw(traces(nan=True))
    fill = data.draw(st.sampled_from([-5.0, 0.0, 5.0]))
    filled = {k: np.where(np.isnan(v), fill, v) for k, v in sig.items()}
    assert np.all(evaluate(expr, sig, period) <= evaluate(expr, filled, period))
    assert not np.any(verdicts(expr, sig, period) & ~verdicts(expr, filled, period))
