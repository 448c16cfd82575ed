"""Quantitative (robustness) semantics of oracle formulas over a sampled trace.

`evaluate` returns the robustness signal rho(t) at every sample time (Donze-Maler
style): rho > 0 means the formula holds at t with margin rho, rho < 0 that it fails.
Every node maps whole numpy arrays; temporal operators use O(n) window kernels, until an
O(n log n) scan, so a formula costs O(n log n) per node whatever its window widths.

Decisions (docs/oracles.md has the long form):
- windows are whole samples, [round(lo/period), round(hi/period)], ties rounded up;
- finite trace: windows are cut off at the trace end; an empty one gives always -> +inf,
  eventually / until -> -inf (the same as rtamt's discrete-time offline monitor);
- verdict: rho > 0 holds, rho < 0 fails, rho == 0 is decided by the exact Boolean
  semantics (so `x >= 0` holds and `x > 0` fails at x == 0); the sign never disagrees;
- NaN (in a signal, or made by arithmetic such as 0/0) turns its comparison into the
  worst value for the whole formula: -inf where the atom occurs positively, +inf under an
  odd number of negations, so a NaN never helps an oracle pass, not even through `not`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from enum import Enum

import numpy as np

from addt_dsl.expr import (Binary, Call, Expr, Num, Param, Signal, Temporal, Unary, UnboundParameter,
                           Until, walk, window_exprs)
from addt_dsl.runtime.oracles.windows import until as _until
from addt_dsl.runtime.oracles.windows import window_reduce

__all__ = [
    "Formula", "FormulaTypeError", "UnknownSignalError", "UnsubstitutedParameterError", "evaluate",
    "first_violation_time", "prepare", "robustness_at_0", "robustness_over_time", "samples", "satisfied", "verdicts",
]


class UnknownSignalError(KeyError):
    """A formula names a signal that the trace doesn't have."""

    def __init__(self, name: str, known: list[str]):
        super().__init__(name)
        self.name = name
        self.known = known

    def __str__(self) -> str:
        hint = f"; the trace has {', '.join(self.known)}" if self.known else "; the trace has no signals"
        return f"unknown signal '{self.name}'{hint}"


class UnsubstitutedParameterError(UnboundParameter):
    def __str__(self) -> str:
        return (f"parameter '{self.args[0]}' is still symbolic: substitute parameters "
                "(addt_dsl.expr.substitute_params) before evaluating a formula")


class FormulaTypeError(TypeError):
    """A value used where a formula is required, or the other way round (`x and 3`)."""


# --- sorts: formulas (truth with a margin) vs. values (physical quantities) -----------

class Sort(Enum):
    VALUE = "value"
    FORMULA = "formula"


_ARITH = frozenset(("+", "-", "*", "/"))
_COMPARE = frozenset(("<", "<=", ">", ">=", "==", "!="))
_CALL_ARITY = {"abs": (1, 1), "sqrt": (1, 1), "min": (1, None), "max": (1, None)}


def sort_of(expr: Expr) -> Sort:
    """Check operand sorts bottom-up; the evaluator relies on formulas never seeing NaN,
    which holds because only comparisons turn values into formulas."""
    match expr:
        case Num() | Signal():
            return Sort.VALUE
        case Param(name=name):
            raise UnsubstitutedParameterError(name)
        case Call(fn=fn, args=args):
            lo, hi = _CALL_ARITY[fn]
            if len(args) < lo or (hi is not None and len(args) > hi):
                raise FormulaTypeError(f"{fn}() takes {lo if lo == hi else f'at least {lo}'} "
                                       f"argument(s), got {len(args)}")
            for a in args:
                _expect(a, Sort.VALUE, f"argument of {fn}()")
            return Sort.VALUE
        case Unary(op="neg", arg=a):
            _expect(a, Sort.VALUE, "operand of unary minus")
            return Sort.VALUE
        case Unary(op="not", arg=a):
            _expect(a, Sort.FORMULA, "operand of 'not'")
            return Sort.FORMULA
        case Binary(op=op, left=l, right=r) if op in _ARITH or op in _COMPARE:
            _expect(l, Sort.VALUE, f"left operand of '{op}'")
            _expect(r, Sort.VALUE, f"right operand of '{op}'")
            return Sort.VALUE if op in _ARITH else Sort.FORMULA
        case Binary(op=op, left=l, right=r):
            _expect(l, Sort.FORMULA, f"left operand of '{op}'")
            _expect(r, Sort.FORMULA, f"right operand of '{op}'")
            return Sort.FORMULA
        case Temporal(op=op, arg=a):
            _numeric_window(expr)
            _expect(a, Sort.FORMULA, f"operand of '{op}'")
            return Sort.FORMULA
        case Until(left=l, right=r):
            _numeric_window(expr)
            _expect(l, Sort.FORMULA, "left operand of 'until'")
            _expect(r, Sort.FORMULA, "right operand of 'until'")
            return Sort.FORMULA
    raise TypeError(f"not an expression node: {expr!r}")


def _numeric_window(expr: Temporal | Until) -> None:
    """A window bound over parameters is a number only once the run's values are substituted."""
    for bound in window_exprs(expr):
        sort_of(bound)  # raises on its first parameter
        raise FormulaTypeError(f"a window bound must be a number of seconds, not {bound!r}")


def _expect(expr: Expr, want: Sort, where: str) -> None:
    got = sort_of(expr)
    if got is not want:
        raise FormulaTypeError(f"{where} must be a {want.value}, not a {got.value}")


# --- time ------------------------------------------------------------------------------

def samples(t_s: float, period_s: float) -> int:
    """Seconds -> whole samples, rounded to the nearest sample, ties up.

    The quotient is first snapped to 9 decimals so float noise can't move a bound
    written in decimal: 0.3 s / 0.1 s is 2.9999999999999996 (-> 3) and 0.95 s / 0.1 s
    is 9.499999999999998, a tie (-> 10)."""
    return math.floor(round(t_s / period_s, 9) + 0.5)


def _window(lo_s: float, hi_s: float | None, period_s: float) -> tuple[int, int | None]:
    if not (math.isfinite(lo_s) and lo_s >= 0) or (hi_s is not None and not hi_s >= lo_s):
        raise ValueError(f"bad time window [{lo_s}, {hi_s}]: need 0 <= lo <= hi, lo finite")
    hi = None if hi_s is None or math.isinf(hi_s) else samples(hi_s, period_s)
    return samples(lo_s, period_s), hi


# --- evaluation ------------------------------------------------------------------------

class _Mode(Enum):
    ROBUST = "robust"    # quantitative semantics
    BOOLEAN = "boolean"  # atoms as +1 / -1: the same min/max algebra computes and/or/not


@dataclass(frozen=True, slots=True)
class _Ctx:
    signals: Mapping[str, np.ndarray]
    n: int
    period_s: float
    mode: _Mode


def _num(node: Num, ctx: _Ctx, pol: int) -> np.ndarray:
    return np.full(ctx.n, node.value)


def _signal(node: Signal, ctx: _Ctx, pol: int) -> np.ndarray:
    try:
        return ctx.signals[node.name]
    except KeyError:
        raise UnknownSignalError(node.name, sorted(ctx.signals)) from None


_CALLS = {
    "abs": lambda xs: np.abs(xs[0]),
    "sqrt": lambda xs: np.sqrt(xs[0]),
    "min": lambda xs: np.minimum.reduce(xs),  # propagates NaN: the atom above catches it
    "max": lambda xs: np.maximum.reduce(xs),
}


def _call(node: Call, ctx: _Ctx, pol: int) -> np.ndarray:
    return _CALLS[node.fn]([_eval(a, ctx, pol) for a in node.args])


def _unary(node: Unary, ctx: _Ctx, pol: int) -> np.ndarray:
    # `not` flips polarity: a NaN atom under it must come out as +inf to end as -inf.
    return -_eval(node.arg, ctx, -pol if node.op == "not" else pol)


# Margin of a comparison: positive iff it holds strictly.
_MARGIN = {
    ">": lambda a, b: a - b, ">=": lambda a, b: a - b,
    "<": lambda a, b: b - a, "<=": lambda a, b: b - a,
    "==": lambda a, b: -np.abs(a - b), "!=": lambda a, b: np.abs(a - b),
}
_HOLDS = {
    ">": np.greater, ">=": np.greater_equal, "<": np.less, "<=": np.less_equal,
    "==": np.equal, "!=": np.not_equal,
}
_ARITH_FN = {"+": np.add, "-": np.subtract, "*": np.multiply, "/": np.divide}
_BOOL_FN = {
    "and": lambda a, b: np.minimum(a, b),
    "or": lambda a, b: np.maximum(a, b),
    "implies": lambda a, b: np.maximum(-a, b),
}


def _binary(node: Binary, ctx: _Ctx, pol: int) -> np.ndarray:
    op = node.op
    left_pol = -pol if op == "implies" else pol
    a, b = _eval(node.left, ctx, left_pol), _eval(node.right, ctx, pol)
    if op in _ARITH_FN:
        return _ARITH_FN[op](a, b)
    if op in _BOOL_FN:
        return _BOOL_FN[op](a, b)
    return _atom(op, a, b, ctx.mode, pol)


def _atom(op: str, a: np.ndarray, b: np.ndarray, mode: _Mode, pol: int) -> np.ndarray:
    margin = _MARGIN[op](a, b)
    # NaN margin (a NaN sample, inf - inf, 0/0 ...): the worst value for the formula.
    unknown = np.isnan(margin)
    if mode is _Mode.BOOLEAN:
        margin = np.where(_HOLDS[op](a, b), 1.0, -1.0)
    return np.where(unknown, -np.inf if pol > 0 else np.inf, margin)


def _temporal(node: Temporal, ctx: _Ctx, pol: int) -> np.ndarray:
    lo, hi = _window(node.lo_s, node.hi_s, ctx.period_s)
    op = np.minimum if node.op == "always" else np.maximum
    return window_reduce(_eval(node.arg, ctx, pol), lo, hi, op)


def _until_node(node: Until, ctx: _Ctx, pol: int) -> np.ndarray:
    lo, hi = _window(node.lo_s, node.hi_s, ctx.period_s)
    return _until(_eval(node.left, ctx, pol), _eval(node.right, ctx, pol), lo, hi)


def _param(node: Param, ctx: _Ctx, pol: int) -> np.ndarray:
    raise UnsubstitutedParameterError(node.name)


_DISPATCH = {
    Num: _num, Signal: _signal, Param: _param, Call: _call, Unary: _unary,
    Binary: _binary, Temporal: _temporal, Until: _until_node,
}


def _eval(expr: Expr, ctx: _Ctx, pol: int) -> np.ndarray:
    return _DISPATCH[type(expr)](expr, ctx, pol)


@dataclass(frozen=True, slots=True)
class Formula:
    """A formula checked once to be evaluated many times (a trigger's condition is asked
    at every sample until it fires): its sort and the signals it reads, sorted. Every
    function below that takes a formula takes an `Expr` or one of these."""
    expr: Expr
    sort: Sort
    signals: tuple[str, ...]


def prepare(expr: Expr | Formula) -> Formula:
    """`expr` checked (`sort_of` raises on a parameter or a sort error) with its signals."""
    if isinstance(expr, Formula):
        return expr
    sort = sort_of(expr)
    return Formula(expr, sort, tuple(sorted({n.name for n in walk(expr) if isinstance(n, Signal)})))


def _context(formula: Formula, signals: Mapping[str, np.ndarray], period_s: float, mode: _Mode) -> _Ctx:
    if not (period_s > 0 and math.isfinite(period_s)):
        raise ValueError(f"sampling period must be positive and finite, got {period_s}")
    arrays: dict[str, np.ndarray] = {}
    for name in formula.signals:
        if name not in signals:
            raise UnknownSignalError(name, sorted(signals))
        arr = np.asarray(signals[name], dtype=np.float64)
        if arr.ndim != 1:
            raise ValueError(f"signal '{name}' must be one-dimensional, has shape {arr.shape}")
        arrays[name] = arr
    lengths = {a.shape[0] for a in arrays.values()}
    if len(lengths) > 1:
        raise ValueError("signals differ in length: " + ", ".join(
            f"{k}={v.shape[0]}" for k, v in arrays.items()))
    if lengths:
        n = lengths.pop()
    else:  # a formula over constants only: as long as the trace, or one sample
        n = len(next(iter(signals.values()))) if signals else 1
    return _Ctx(arrays, n, float(period_s), mode)


def _run(expr: Expr | Formula, signals, period_s, mode: _Mode, need: Sort | None) -> np.ndarray:
    formula = prepare(expr)
    if need is not None and formula.sort is not need:
        raise FormulaTypeError(f"expected a {need.value}, got a {formula.sort.value}")
    ctx = _context(formula, signals, period_s, mode)
    with np.errstate(all="ignore"):  # x/0, inf-inf, sqrt(-1) are handled as values/NaN
        out = _eval(formula.expr, ctx, +1)
    # Constants broadcast as full arrays already; signals are returned as given: copy
    # so callers can't alias (and mutate) the trace.
    return np.array(out, dtype=np.float64, copy=True)


def evaluate(expr: Expr | Formula, signals: Mapping[str, np.ndarray], period_s: float) -> np.ndarray:
    """Robustness of a formula (or the value of a value expression) at every sample."""
    return _run(expr, signals, period_s, _Mode.ROBUST, None)


def robustness_at_0(expr: Expr | Formula, signals: Mapping[str, np.ndarray], period_s: float) -> float:
    rho = _run(expr, signals, period_s, _Mode.ROBUST, Sort.FORMULA)
    if rho.shape[0] == 0:
        raise ValueError("empty trace: no sample at time 0")
    return float(rho[0])


def verdicts(expr: Expr | Formula, signals: Mapping[str, np.ndarray], period_s: float) -> np.ndarray:
    """Boolean verdict at every sample: the sign of rho, and where rho == 0 exactly the
    Boolean semantics (only then is the second, +1/-1 evaluation paid for)."""
    expr = prepare(expr)
    rho = _run(expr, signals, period_s, _Mode.ROBUST, Sort.FORMULA)
    out = rho > 0
    ties = rho == 0
    if ties.any():
        out[ties] = _run(expr, signals, period_s, _Mode.BOOLEAN, Sort.FORMULA)[ties] > 0
    return out


def boolean_semantics(expr: Expr, signals: Mapping[str, np.ndarray], period_s: float) -> np.ndarray:
    """The plain Boolean semantics, computed on its own (for tests and tie-breaking)."""
    return _run(expr, signals, period_s, _Mode.BOOLEAN, Sort.FORMULA) > 0


def satisfied(expr: Expr | Formula, signals: Mapping[str, np.ndarray], period_s: float) -> bool:
    v = verdicts(expr, signals, period_s)
    if v.shape[0] == 0:
        raise ValueError("empty trace: no sample at time 0")
    return bool(v[0])


def first_violation_time(expr: Expr | Formula, signals: Mapping[str, np.ndarray],
                         period_s: float) -> float | None:
    """When the violation of a violated formula became certain (None if it holds at time
    0, or if no single instant can be named).

    `always φ`: the first sample of its window (from time 0) where φ fails;
    `eventually [a, b] φ`: the window end b, or the end of the run when that comes first or
    there is no b (φ never held, and only then is that known); a conjunction: the earliest
    among its violated conjuncts; a disjunction: when the later of its two violations
    became certain; a comparison with no temporal operator: 0.0, the time it is judged at.
    """
    formula = prepare(expr)
    if satisfied(formula, signals, period_s):
        return None
    return _violation_time(formula.expr, signals, period_s)


def _violation_time(expr: Expr, signals: Mapping[str, np.ndarray], period_s: float) -> float | None:
    """`first_violation_time` of a formula known to be violated at time 0."""
    match expr:
        case Temporal(op="always", lo_s=lo_s, hi_s=hi_s, arg=arg):
            v = verdicts(arg, signals, period_s)
            lo, hi = _window(lo_s, hi_s, period_s)
            end = v.shape[0] if hi is None else min(hi + 1, v.shape[0])
            bad = np.flatnonzero(~v[lo:end])
            return (lo + int(bad[0])) * period_s
        case Temporal(op="eventually", hi_s=hi_s):
            last = (_length(signals) - 1) * period_s
            return last if hi_s is None else min(samples(hi_s, period_s) * period_s, last)
        case Binary(op="and", left=l, right=r):
            times = [t for t in (first_violation_time(e, signals, period_s) for e in (l, r))
                     if t is not None]
            return min(times)
        case Binary(op="or", left=l, right=r):  # both sides are violated
            times = [_violation_time(e, signals, period_s) for e in (l, r)]
            return None if None in times else max(times)
        case Binary(op="<" | "<=" | ">" | ">=" | "==" | "!="):
            return 0.0
    return None


def _length(signals: Mapping[str, np.ndarray]) -> int:
    return max((np.asarray(v).shape[0] for v in signals.values()), default=1)


def robustness_over_time(expr: Expr, signals: Mapping[str, np.ndarray], period_s: float) -> np.ndarray:
    """The oracle's margin at every sample, for plots: for `always φ` / `eventually φ` the
    robustness of φ at each sample (negative where φ fails: the samples that break an
    `always`, or every sample of an `eventually` that never held), else the formula's own
    robustness judged at each sample."""
    match expr:
        case Temporal(arg=arg):
            return evaluate(arg, signals, period_s)
    return evaluate(expr, signals, period_s)
