"""Expression and formula trees shared by the plan, the compiler and the oracles.

Values in a plan that depend on parameters (`20 m + gap`) and oracle formulas
(`always during [0 s, 10 s] ttc(ego, lead) > 1 s`) are both `Expr` trees. Numbers are SI.
`Param` names a scenario parameter, `Signal` names a trace signal by its canonical
name (e.g. `ego.speed`, `ttc(ego,lead)`, `latency(e2e)`). Pure data: no evaluation of
signals here (runtime/oracles does that), only of parameter expressions.
"""

from __future__ import annotations

import math
from typing import Annotated, Literal, Union

from pydantic import BaseModel, ConfigDict, Field


class _Node(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


class Num(_Node):
    kind: Literal["num"] = "num"
    value: float


class Param(_Node):
    kind: Literal["param"] = "param"
    name: str


class Signal(_Node):
    kind: Literal["signal"] = "signal"
    name: str


class Call(_Node):
    """Pure arithmetic functions: abs, min, max, sqrt."""

    kind: Literal["call"] = "call"
    fn: Literal["abs", "min", "max", "sqrt"]
    args: tuple[Expr, ...]


class Unary(_Node):
    kind: Literal["unary"] = "unary"
    op: Literal["neg", "not"]
    arg: Expr


COMPARE_OPS = ("<", "<=", ">", ">=", "==", "!=")
BOOL_OPS = ("and", "or", "implies")


class Binary(_Node):
    kind: Literal["binary"] = "binary"
    op: Literal["+", "-", "*", "/", "<", "<=", ">", ">=", "==", "!=", "and", "or", "implies"]
    left: Expr
    right: Expr


class Temporal(_Node):
    """`always` / `eventually` over the window [t + lo_s, t + hi_s]; hi_s None = to the end.

    A bound is a number [s], or an expression over parameters (`during [0 s, t_end]`) that
    `substitute_params` turns into its number for a run."""

    kind: Literal["temporal"] = "temporal"
    op: Literal["always", "eventually"]
    lo_s: float | Expr = 0.0
    hi_s: float | Expr | None = None
    arg: Expr


class Until(_Node):
    """`left until right` with right required within [t + lo_s, t + hi_s] (bounds as in `Temporal`)."""

    kind: Literal["until"] = "until"
    lo_s: float | Expr = 0.0
    hi_s: float | Expr | None = None
    left: Expr
    right: Expr


Expr = Annotated[Union[Num, Param, Signal, Call, Unary, Binary, Temporal, Until],
                 Field(discriminator="kind")]

for _model in (Call, Unary, Binary, Temporal, Until):
    _model.model_rebuild()


class UnboundParameter(KeyError):
    pass


def eval_param_expr(expr: Expr, params: dict[str, float]) -> float:
    """Evaluate an arithmetic expression over parameters (no signals, no time)."""
    match expr:
        case Num(value=v):
            return v
        case Param(name=n):
            try:
                return params[n]
            except KeyError:
                raise UnboundParameter(n) from None
        case Unary(op="neg", arg=a):
            return -eval_param_expr(a, params)
        case Unary(op="not", arg=a):
            return float(not eval_param_expr(a, params))
        case Call(fn=fn, args=args):
            vals = [eval_param_expr(a, params) for a in args]
            return {"abs": lambda: abs(vals[0]), "min": lambda: min(vals),
                    "max": lambda: max(vals), "sqrt": lambda: math.sqrt(vals[0])}[fn]()
        case Binary(op=op, left=l, right=r):
            a, b = eval_param_expr(l, params), eval_param_expr(r, params)
            return _BINARY[op](a, b)
    raise TypeError(f"not a parameter expression: {expr!r}")


_BINARY = {
    "+": lambda a, b: a + b,
    "-": lambda a, b: a - b,
    "*": lambda a, b: a * b,
    "/": lambda a, b: a / b if b != 0 else math.copysign(math.inf, a) if a else math.nan,
    "<": lambda a, b: float(a < b),
    "<=": lambda a, b: float(a <= b),
    ">": lambda a, b: float(a > b),
    ">=": lambda a, b: float(a >= b),
    "==": lambda a, b: float(a == b),
    "!=": lambda a, b: float(a != b),
    "and": lambda a, b: float(bool(a) and bool(b)),
    "or": lambda a, b: float(bool(a) or bool(b)),
    "implies": lambda a, b: float((not a) or bool(b)),
}


def walk(expr: Expr):
    """Yield every node of the tree, parents first (a window's bound expressions after
    their operator, before its operands)."""
    yield expr
    for bound in window_exprs(expr):
        yield from walk(bound)
    for child in children(expr):
        yield from walk(child)


def window_exprs(expr: Expr) -> tuple:
    """The bounds of a temporal operator's window that are expressions over parameters."""
    if isinstance(expr, (Temporal, Until)):
        return tuple(b for b in (expr.lo_s, expr.hi_s) if b is not None and not isinstance(b, float))
    return ()


def window_problem(lo_s: float, hi_s: float | None, duration_s: float | None = None) -> tuple[str, str] | None:
    """What is wrong with a window of resolved bounds [s], as (kind, text), or None: a bound
    that is not a finite time >= 0 (`bound`), an end before the start (`inverted`), an end
    beyond the scenario's duration (`beyond`). The compiler and the per-run binding both
    judge windows by this."""
    for b in (lo_s, hi_s):
        if b is not None and not (math.isfinite(b) and b >= 0.0):
            return "bound", "a window bound must be a finite time >= 0 s"
    if hi_s is not None and hi_s < lo_s:
        return "inverted", "the window ends before it starts"
    for b in (lo_s, hi_s):
        if duration_s is not None and b is not None and b > duration_s + 1e-9:
            return "beyond", f"the time window reaches {b:g} s, beyond the scenario's duration ({duration_s:g} s)"
    return None


def children(expr: Expr) -> tuple:
    match expr:
        case Call(args=args):
            return tuple(args)
        case Unary(arg=a) | Temporal(arg=a):
            return (a,)
        case Binary(left=l, right=r) | Until(left=l, right=r):
            return (l, r)
    return ()


def params_used(expr: Expr) -> set[str]:
    return {n.name for n in walk(expr) if isinstance(n, Param)}


def signals_used(expr: Expr) -> set[str]:
    return {n.name for n in walk(expr) if isinstance(n, Signal)}


def substitute_params(expr: Expr, params: dict[str, float]) -> Expr:
    """Replace every `Param` by its value (used to make a formula concrete for a run)."""
    match expr:
        case Param(name=n):
            if n not in params:
                raise UnboundParameter(n)
            return Num(value=params[n])
        case Num() | Signal():
            return expr
        case Call(fn=fn, args=args):
            return Call(fn=fn, args=tuple(substitute_params(a, params) for a in args))
        case Unary(op=op, arg=a):
            return Unary(op=op, arg=substitute_params(a, params))
        case Binary(op=op, left=l, right=r):
            return Binary(op=op, left=substitute_params(l, params), right=substitute_params(r, params))
        case Temporal(op=op, lo_s=lo, hi_s=hi, arg=a):
            return Temporal(op=op, lo_s=_bound_value(lo, params), hi_s=_bound_value(hi, params),
                            arg=substitute_params(a, params))
        case Until(lo_s=lo, hi_s=hi, left=l, right=r):
            return Until(lo_s=_bound_value(lo, params), hi_s=_bound_value(hi, params),
                         left=substitute_params(l, params), right=substitute_params(r, params))
    raise TypeError(f"unknown node {expr!r}")


def _bound_value(bound, params: dict[str, float]):
    """A window bound as a number [s] (a number stays the same object: float windows keep
    their exact value)."""
    if bound is None or isinstance(bound, float):
        return bound
    return float(eval_param_expr(bound, params))
