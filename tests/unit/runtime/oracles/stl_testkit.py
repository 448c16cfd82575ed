"""Shared test kit: Hypothesis strategies for formulas and traces, and a slow,
obviously-correct reference implementation of the semantics (definition by the book:
one loop per quantifier, no cleverness)."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import strategies as st

from addt_dsl import units
from addt_dsl.compiler.formula import parse_formula
from addt_dsl.expr import Binary, Call, Num, Signal, Temporal, Unary, Until
from addt_dsl.runtime.oracles import robustness_at_0
from addt_dsl.runtime.oracles.stl import samples

SIGNALS = ("x", "y", "z")
PERIODS = (1.0, 0.1, 0.05, 0.02)
COMPARE = ("<", "<=", ">", ">=", "==", "!=")



def parse(text: str, signals=SIGNALS):
    """A formula over synthetic signals (`x`, `y`, `z`: plain numbers) and registered ones."""
    return parse_formula(text, signals={name: units.DIMENSIONLESS for name in signals})


def robustness(text: str, signals: dict, period_s: float) -> float:
    """Robustness at time 0 of a formula given as text (parsed by the compiler)."""
    return robustness_at_0(parse(text, {*SIGNALS, *signals}), signals, period_s)


# Few distinct values so that ties (robustness exactly 0) happen often.
values = st.sampled_from([-2.0, -1.0, -0.5, 0.0, 0.5, 1.0, 2.0, 3.0])
constants = st.sampled_from([-1.0, -0.5, 0.0, 0.5, 1.0, 2.0])


@st.composite
def traces(draw, min_len=1, max_len=24, nan=False):
    n = draw(st.integers(min_len, max_len))
    elem = st.one_of(values, st.just(math.nan)) if nan else values
    return {s: np.array(draw(st.lists(elem, min_size=n, max_size=n))) for s in SIGNALS}


def value_exprs(arith: bool):
    sig = st.sampled_from(SIGNALS).map(lambda s: Signal(name=s))
    if not arith:
        return sig
    two = st.tuples(sig, sig)
    return st.one_of(
        sig,
        st.builds(lambda op, ab: Binary(op=op, left=ab[0], right=ab[1]), st.sampled_from("+-"), two),
        sig.map(lambda s: Call(fn="abs", args=(s,))),
    )


def atoms(arith: bool = False):
    def build(op, v, c, flip):
        left, right = (Num(value=c), v) if flip else (v, Num(value=c))
        return Binary(op=op, left=left, right=right)
    return st.builds(build, st.sampled_from(COMPARE), value_exprs(arith), constants, st.booleans())


@st.composite
def windows(draw, period: float, max_lo: int = 5, max_width: int = 8):
    """Whole-sample windows as seconds: (lo_s, hi_s or None)."""
    lo = draw(st.integers(0, max_lo))
    hi = draw(st.one_of(st.none(), st.integers(lo, lo + max_width)))
    return lo * period, (None if hi is None else hi * period)


def formulas(period: float, arith: bool = False, max_leaves: int = 8):
    def extend(sub):
        win = windows(period)
        return st.one_of(
            sub.map(lambda a: Unary(op="not", arg=a)),
            st.builds(lambda op, a, b: Binary(op=op, left=a, right=b),
                      st.sampled_from(("and", "or", "implies")), sub, sub),
            st.builds(lambda op, w, a: Temporal(op=op, lo_s=w[0], hi_s=w[1], arg=a),
                      st.sampled_from(("always", "eventually")), win, sub),
            st.builds(lambda w, a, b: Until(lo_s=w[0], hi_s=w[1], left=a, right=b), win, sub, sub),
        )
    return st.recursive(atoms(arith), extend, max_leaves=max_leaves)


# --- reference semantics ------------------------------------------------------------------

def _value(e, sig, t):
    match e:
        case Num(value=v):
            return v
        case Signal(name=n):
            return float(sig[n][t])
        case Call(fn="abs", args=(a,)):
            return abs(_value(a, sig, t))
        case Binary(op="+", left=l, right=r):
            return _value(l, sig, t) + _value(r, sig, t)
        case Binary(op="-", left=l, right=r):
            return _value(l, sig, t) - _value(r, sig, t)
    raise NotImplementedError(e)


_MARGIN = {">": lambda a, b: a - b, ">=": lambda a, b: a - b, "<": lambda a, b: b - a,
           "<=": lambda a, b: b - a, "==": lambda a, b: -abs(a - b), "!=": lambda a, b: abs(a - b)}
_HOLDS = {">": lambda a, b: a > b, ">=": lambda a, b: a >= b, "<": lambda a, b: a < b,
          "<=": lambda a, b: a <= b, "==": lambda a, b: a == b, "!=": lambda a, b: a != b}


def _window(lo_s, hi_s, period, t, n):
    lo = samples(lo_s, period)
    hi = n - 1 if hi_s is None else samples(hi_s, period)
    return range(t + lo, min(t + hi, n - 1) + 1)  # cut off at the trace end


def reference(e, sig, period, t, n, boolean=False, pol=1):
    """rho(e, t) by the book; boolean=True gives +1/-1 truth values instead."""
    rec = lambda x, tt=t, p=pol: reference(x, sig, period, tt, n, boolean, p)  # noqa: E731
    match e:
        case Binary(op=op, left=l, right=r) if op in _MARGIN:
            a, b = _value(l, sig, t), _value(r, sig, t)
            m = _MARGIN[op](a, b)
            if math.isnan(m):
                return -math.inf if pol > 0 else math.inf
            return (1.0 if _HOLDS[op](a, b) else -1.0) if boolean else m
        case Unary(op="not", arg=a):
            return -rec(a, t, -pol)
        case Binary(op="and", left=l, right=r):
            return min(rec(l), rec(r))
        case Binary(op="or", left=l, right=r):
            return max(rec(l), rec(r))
        case Binary(op="implies", left=l, right=r):
            return max(-rec(l, t, -pol), rec(r))
        case Temporal(op="always", lo_s=lo, hi_s=hi, arg=a):
            return min((rec(a, tt) for tt in _window(lo, hi, period, t, n)), default=math.inf)
        case Temporal(op="eventually", lo_s=lo, hi_s=hi, arg=a):
            return max((rec(a, tt) for tt in _window(lo, hi, period, t, n)), default=-math.inf)
        case Until(lo_s=lo, hi_s=hi, left=l, right=r):
            best = -math.inf
            for t1 in _window(lo, hi, period, t, n):
                left_min = min((rec(l, t2) for t2 in range(t, t1)), default=math.inf)
                best = max(best, min(rec(r, t1), left_min))
            return best
    raise NotImplementedError(e)


def reference_signal(e, sig, period, boolean=False):
    n = len(next(iter(sig.values())))
    return np.array([reference(e, sig, period, t, n, boolean) for t in range(n)])
