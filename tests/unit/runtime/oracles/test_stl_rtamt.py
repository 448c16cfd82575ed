"""Cross-check against rtamt's discrete-time offline STL monitor (test-only dependency).

Fragment where the semantics coincide, and so what is generated here: comparisons
(< <= > >= == !=) between constants and signals or `x + y`, `x - y`, `abs(x)`;
not / and / or / implies; always / eventually with [a, b], [a, end) and [0, end)
windows; until with the same windows; windows in whole samples; no NaN.
Outside it: NaN (rtamt's Python min/max depend on argument order; ours are the worst
case), division, min/max/sqrt calls (rtamt has no min/max), and non-integral windows
(rtamt rejects a bound that isn't a multiple of the period; we round), and
1-sample traces (rtamt 0.4.10 crashes on them: UnboundLocalError in evaluate).
"""

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from tests.unit.runtime.oracles.stl_testkit import formulas, robustness, traces

from addt_dsl.expr import Binary, Call, Num, Signal, Temporal, Unary, Until
from addt_dsl.runtime.oracles import robustness_at_0
from addt_dsl.runtime.oracles.stl import samples

rtamt = pytest.importorskip("rtamt")

PERIODS_MS = (1000, 100, 50)
_RT_OPS = {"<": "<", "<=": "<=", ">": ">", ">=": ">=", "==": "==", "!=": "!==",
           "and": "and", "or": "or", "implies": "implies", "+": "+", "-": "-"}


def to_rtamt(e, period_ms: int, n: int) -> str:
    """Render a tree in rtamt's specification language (fully parenthesised)."""
    def bounds(lo_s, hi_s, period_s):
        lo = samples(lo_s, period_s)
        if hi_s is None and lo == 0:
            return ""
        # [a, end): any bound past the last sample means "to the end" in both tools.
        hi = max(n, lo) if hi_s is None else samples(hi_s, period_s)
        return f"[{lo * period_ms}ms:{hi * period_ms}ms]"
    r = lambda x: to_rtamt(x, period_ms, n)  # noqa: E731
    p = period_ms / 1000
    match e:
        case Num(value=v):
            return repr(v)
        case Signal(name=s):
            return s
        case Call(fn="abs", args=(a,)):
            return f"abs({r(a)})"
        case Unary(op="not", arg=a):
            return f"not({r(a)})"
        case Binary(op=op, left=l, right=rr):
            return f"({r(l)}) {_RT_OPS[op]} ({r(rr)})"
        case Temporal(op=op, lo_s=lo, hi_s=hi, arg=a):
            return f"{op}{bounds(lo, hi, p)}({r(a)})"
        case Until(lo_s=lo, hi_s=hi, left=l, right=rr):
            return f"({r(l)}) until{bounds(lo, hi, p)} ({r(rr)})"
    raise NotImplementedError(e)


def rtamt_robustness(text: str, sig: dict, period_ms: int) -> float:
    spec = rtamt.StlDiscreteTimeOfflineSpecification()
    for name in sig:
        spec.declare_var(name, "float")
    spec.set_sampling_period(period_ms, "ms", 0.1)
    spec.spec = text
    spec.parse()
    n = len(next(iter(sig.values())))
    # Fresh lists: rtamt pads some of its inputs in place.
    data = {"time": [i * period_ms / 1000 for i in range(n)],
            **{k: [float(x) for x in v] for k, v in sig.items()}}
    return spec.evaluate(data)[0][1]


def _same(a: float, b: float) -> bool:
    return a == b or (math.isfinite(a) and math.isfinite(b) and abs(a - b) <= 1e-9)


@st.composite
def cases(draw):
    period_ms = draw(st.sampled_from(PERIODS_MS))
    return draw(formulas(period_ms / 1000, arith=True, max_leaves=6)), draw(traces(min_len=2, max_len=16)), period_ms


@settings(max_examples=300, deadline=None)
@given(cases())
def test_robustness_at_0_agrees_with_rtamt(case):
    expr, sig, period_ms = case
    n = len(sig["x"])
    text = to_rtamt(expr, period_ms, n)
    ours = robustness_at_0(expr, sig, period_ms / 1000)
    theirs = rtamt_robustness(text, sig, period_ms)
    assert _same(ours, theirs), f"{text}: ours {ours}, rtamt {theirs}"


@pytest.mark.parametrize("text, rt_text", [
    ("always during [1 s, 3 s] x > 0", "always[1s:3s](x > 0)"),
    ("eventually within 2 s x > 2", "eventually[0s:2s](x > 2)"),
    ("x > 0 until during [1 s, 2 s] y > 0", "(x > 0) until[1s:2s] (y > 0)"),
    ("not (eventually (x > 1 and y < 0))", "not(eventually((x > 1) and (y < 0)))"),
])
def test_hand_written_examples_agree_with_rtamt(text, rt_text):
    sig = {"x": [1.0, -2.0, 3.0, 0.5, 2.5], "y": [0.0, 1.0, -1.0, 2.0, -3.0]}
    assert _same(robustness(text, sig, 1.0), rtamt_robustness(rt_text, sig, 1000))
