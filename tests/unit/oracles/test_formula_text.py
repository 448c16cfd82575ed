"""The formula text parser and printer."""

import math
import re

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from addt_dsl.expr import Binary, Call, Num, Param, Signal, Temporal, Unary, Until
from addt_dsl.runtime.oracles import FormulaSyntaxError, format_formula, parse_formula
from addt_dsl.runtime.oracles.formula_text import FUNCTIONS, KEYWORDS

x, y, z = (Signal(name=n) for n in "xyz")
zero = Num(value=0.0)


def gt(a, b=zero):
    return Binary(op=">", left=a, right=b)


def B(op, a, b):
    return Binary(op=op, left=a, right=b)


@pytest.mark.parametrize("text, want", [
    ("x > 0", gt(x)),
    ("ego.speed < 30 km/h", B("<", Signal(name="ego.speed"), Num(value=30 / 3.6))),
    ("ttc(ego, lead) > 1 s", gt(Signal(name="ttc(ego,lead)"), Num(value=1.0))),
    ("lane_offset(ego) <= 1.8 m", B("<=", Signal(name="lane_offset(ego)"), Num(value=1.8))),
    ("latency(e2e) < 100 ms", B("<", Signal(name="latency(e2e)"), Num(value=0.1))),
    ("x > 5 %", gt(x, Num(value=0.05))),
    ("x > 2min", gt(x, Num(value=120.0))),
    ("x < 0.5 m/s^2", B("<", x, Num(value=0.5))),
    ("x > 2 m/y", gt(x, B("/", Num(value=2.0), y))),  # `m/y` is no unit: 2 m, divided by y
    ("min(x, y) > -1", gt(Call(fn="min", args=(x, y)), Num(value=-1.0))),
    ("-x > -(1)", gt(Unary(op="neg", arg=x), Unary(op="neg", arg=Num(value=1.0)))),
    ("x - -1 * y > 0", gt(B("-", x, B("*", Num(value=-1.0), y)))),
    ("-x * y > 0", gt(B("*", Unary(op="neg", arg=x), y))),
    ("x + y * z > 0", gt(B("+", x, B("*", y, z)))),
    ("x - y - z > 0", gt(B("-", B("-", x, y), z))),
    # boolean precedence: implies < or < and < until < not < comparison
    ("x > 0 or y > 0 and z > 0", B("or", gt(x), B("and", gt(y), gt(z)))),
    ("x > 0 implies y > 0 implies z > 0", B("implies", gt(x), B("implies", gt(y), gt(z)))),
    ("not x > 0 and y > 0", B("and", Unary(op="not", arg=gt(x)), gt(y))),
    ("x > 0 and y > 0 until z > 0", B("and", gt(x), Until(left=gt(y), right=gt(z)))),
    ("not x > 0 until y > 0", Until(left=Unary(op="not", arg=gt(x)), right=gt(y))),
    ("x > 0 until y > 0 until z > 0", Until(left=gt(x), right=Until(left=gt(y), right=gt(z)))),
    # temporal operators extend as far right as possible
    ("always x > 0 and y > 0", Temporal(op="always", arg=B("and", gt(x), gt(y)))),
    ("(always x > 0) and y > 0", B("and", Temporal(op="always", arg=gt(x)), gt(y))),
    ("x > 0 implies eventually y > 0 or z > 0",
     B("implies", gt(x), Temporal(op="eventually", arg=B("or", gt(y), gt(z))))),
    ("always during [2 s, 5 s] x > 0", Temporal(op="always", lo_s=2.0, hi_s=5.0, arg=gt(x))),
    ("eventually within 40 s ego.s > 900 m",
     Temporal(op="eventually", hi_s=40.0, arg=gt(Signal(name="ego.s"), Num(value=900.0)))),
    ("always after 100 ms x > 0", Temporal(op="always", lo_s=0.1, arg=gt(x))),
    ("x > 0 until within 5 s y > 0", Until(hi_s=5.0, left=gt(x), right=gt(y))),
    ("x > 0 until during [1 s, 2 s] y > 0", Until(lo_s=1.0, hi_s=2.0, left=gt(x), right=gt(y))),
    ("not always eventually x > 0",
     Unary(op="not", arg=Temporal(op="always", arg=Temporal(op="eventually", arg=gt(x))))),
])
def test_parse(text, want):
    assert parse_formula(text) == want
    assert parse_formula(format_formula(want)) == want


def test_params():
    assert parse_formula("x > gap + 1 m", params={"gap"}) == gt(x, B("+", Param(name="gap"), Num(value=1.0)))


@pytest.mark.parametrize("text, column, message", [
    ("x >", 4, "expected a number"),
    ("x > 0 y", 7, "unexpected text"),
    ("x > 1 < 2", 7, "don't chain"),
    ("always within 5 x > 0", 15, "time unit"),
    ("always within 5 m x > 0", 15, "time unit"),
    ("always during [3 s, 2 s] x > 0", 15, "empty interval"),
    ("always during [3 s 2 s] x > 0", 20, "expected ','"),
    ("(x > 0", 7, "expected ')'"),
    ("x > 0 and", 10, "expected a number"),
    ("x # 1", 3, "unexpected character"),
    ("and > 1", 1, "expected a number"),
    ("ttc(ego, 2 m) > 0", 10, "signal argument"),
    ("abs(x, y) > 0", 1, "one argument"),
])
def test_syntax_errors_carry_the_column(text, column, message):
    with pytest.raises(FormulaSyntaxError, match=re.escape(message)) as err:
        parse_formula(text)
    assert err.value.column == column
    assert f"column {column}" in str(err.value)
    assert isinstance(err.value, ValueError)


def test_printer_output_is_readable():
    e = parse_formula("always during [2 s, 5 s] ttc(ego, lead) > 1 s and not x < -3")
    assert format_formula(e) == "always during [2 s, 5 s] ttc(ego,lead) > 1 and not x < -3"
    assert format_formula(parse_formula("(always x > 0) and eventually within 500 ms y > 0")) == \
        "(always x > 0) and eventually within 0.5 s y > 0"


def test_printer_refuses_what_has_no_syntax():
    with pytest.raises(ValueError):
        format_formula(gt(x, Num(value=math.nan)))
    with pytest.raises(ValueError):
        format_formula(gt(Signal(name="has space")))
    with pytest.raises(ValueError):
        format_formula(gt(Signal(name="until")))


# --- round trip over arbitrary trees (sorts deliberately ignored) -------------------------

_ident = st.from_regex(r"[a-z_][a-z0-9_]{0,5}", fullmatch=True).filter(lambda s: s not in KEYWORDS)
PARAMS = frozenset({"gap", "v0"})
_plain = st.lists(_ident, min_size=1, max_size=3).map(".".join).filter(lambda s: s not in PARAMS)
_call_name = st.builds(lambda f, args: f"{f}({','.join(args)})",
                       _ident.filter(lambda s: s not in FUNCTIONS),
                       st.lists(st.one_of(_plain, st.integers(0, 99).map(str)), min_size=1, max_size=3))
leaves = st.one_of(
    st.floats(allow_nan=False).map(lambda v: Num(value=v)),
    st.one_of(_plain, _call_name).map(lambda s: Signal(name=s)),
    st.sampled_from(sorted(PARAMS)).map(lambda s: Param(name=s)),
)
_bound = st.floats(0, 1e4, allow_nan=False)


@st.composite
def _window(draw):
    lo = draw(_bound)
    hi = draw(st.one_of(st.none(), st.just(math.inf), _bound.map(lambda d: lo + d)))
    return lo, hi


def _trees(sub):
    return st.one_of(
        st.builds(lambda op, a: Unary(op=op, arg=a), st.sampled_from(["neg", "not"]), sub),
        st.builds(lambda op, a, b: Binary(op=op, left=a, right=b), st.sampled_from(
            ["+", "-", "*", "/", "<", "<=", ">", ">=", "==", "!=", "and", "or", "implies"]), sub, sub),
        st.builds(lambda fn, args: Call(fn=fn, args=tuple(args)), st.sampled_from(["min", "max"]),
                  st.lists(sub, min_size=1, max_size=3)),
        st.builds(lambda fn, a: Call(fn=fn, args=(a,)), st.sampled_from(["abs", "sqrt"]), sub),
        st.builds(lambda op, w, a: Temporal(op=op, lo_s=w[0], hi_s=w[1], arg=a),
                  st.sampled_from(["always", "eventually"]), _window(), sub),
        st.builds(lambda w, a, b: Until(lo_s=w[0], hi_s=w[1], left=a, right=b), _window(), sub, sub),
    )


trees = st.recursive(leaves, _trees, max_leaves=12)


@settings(max_examples=1000, deadline=None)
@given(trees)
def test_parse_format_round_trip(expr):
    text = format_formula(expr)
    assert parse_formula(text, params=PARAMS) == expr, text
    assert format_formula(parse_formula(text, params=PARAMS)) == text
