"""Typing and lowering of expressions: AST expression → (`Expr`, type), with diagnostics.

A type is ("num", Dim) for arithmetic values or ("bool", None) for formulas. Dimensions
are checked here: a speed where a length is needed is error E0201.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from addt_dsl import expr as E
from addt_dsl import units
from addt_dsl.compiler import ast
from addt_dsl.diagnostics import DiagnosticSink
from addt_dsl.plan import LIGHT_STATES
from addt_dsl.registry import SIGNALS
from addt_dsl.units import Dim

BOOL = ("bool", None)

ARITH_FUNCS = ("abs", "min", "max", "sqrt")


@dataclass
class Scope:
    """Names an expression may refer to."""

    params: dict[str, Dim]  # parameter name → dimension
    actors: set[str]
    nodes: set[str]  # stack nodes with a latency signal, plus "e2e"
    allow_signals: bool  # formulas and triggers: yes; placement values: no
    used_params: set[str]
    # Trace signals named directly (`x`, for formulas over synthetic traces given on their
    # own, see compiler.formula); a scenario has none.
    named_signals: dict[str, Dim] = field(default_factory=dict)
    steps: set[str] = field(default_factory=set)  # named steps, `lead.brake_hard`
    lights: set[str] = field(default_factory=set)  # traffic-light controllers: `light(west)`
    variables: set[str] = field(default_factory=set)  # scenario variables: `var(phase)`


def _ty_str(ty) -> str:
    return "a boolean formula" if ty[0] == "bool" else f"a {units.dim_name(ty[1])}"


class ExprLowering:
    def __init__(self, sink: DiagnosticSink, scope: Scope):
        self.sink = sink
        self.scope = scope

    def lower(self, node: ast.Expression):
        """Return (Expr, type) or (None, None) after reporting a diagnostic."""
        method = getattr(self, "_" + type(node).__name__, None)
        if method is None:
            self.sink.error("E0204", "this kind of value is not allowed here", node.span)
            return None, None
        return method(node)

    def lower_value(self, node: ast.Expression, want: Dim, what: str):
        """Lower an arithmetic value that must have dimension `want`."""
        expr, ty = self.lower(node)
        if expr is None:
            return None
        if ty[0] != "num":
            self.sink.error("E0203", f"{what} must be a number, not a formula", node.span)
            return None
        if ty[1] != want:
            self._dim_error(node, want, ty[1], what)
            return None
        return expr

    def lower_formula(self, node: ast.Expression, what: str = "an oracle"):
        expr, ty = self.lower(node)
        if expr is None:
            return None
        if ty != BOOL:
            self.sink.error("E0203", f"{what} must be a boolean formula, found {_ty_str(ty)}",
                            node.span, "compare it with something, e.g. `... > 1 s`")
            return None
        return expr

    def _dim_error(self, node, want: Dim, got: Dim, what: str) -> None:
        hint = []
        if got == units.DIMENSIONLESS and want != units.DIMENSIONLESS:
            canon = units.CANONICAL_UNIT.get(want)
            if canon:
                hint.append(f"add a unit, e.g. `{canon}`")
        self.sink.error("E0201", f"{what} needs a {units.dim_name(want)}, found a {units.dim_name(got)}",
                        node.span, *hint, label=f"this is a {units.dim_name(got)}")

    # ---- atoms
    def _Number(self, node: ast.Number):
        if node.unit is None:
            value, dim = node.value, units.DIMENSIONLESS
        else:
            try:
                value, dim = units.to_si(node.value, node.unit)
            except units.UnknownUnit:
                self.sink.error("E0202", f"unknown unit '{node.unit}'", node.span)
                return None, None
        if not math.isfinite(value):  # 1e999, or 1e308 km in metres: refused where it is read
            self.sink.error("E0204", "this number is not finite", node.span,
                            "numbers must lie within ±1.7e308 (in SI units)")
            return None, None
        return E.Num(value=value), ("num", dim)

    def _Bool(self, node: ast.Bool):
        return E.Num(value=1.0 if node.value else -1.0), BOOL

    def _Ref(self, node: ast.Ref):
        parts = node.parts
        if len(parts) == 1 and parts[0] in self.scope.named_signals and self.scope.allow_signals:
            return E.Signal(name=parts[0]), ("num", self.scope.named_signals[parts[0]])
        if len(parts) == 1 and parts[0] in self.scope.params:
            self.scope.used_params.add(parts[0])
            return E.Param(name=parts[0]), ("num", self.scope.params[parts[0]])
        if len(parts) == 2 and parts[0] in self.scope.actors:
            return self._signal(node, parts[1], (parts[0],))
        if len(parts) == 1 and parts[0] in LIGHT_STATES and self.scope.lights and self.scope.allow_signals:
            return E.Num(value=LIGHT_STATES[parts[0]]), ("num", units.DIMENSIONLESS)  # `light(west) == red`
        if len(parts) == 1 and parts[0] in self.scope.actors:
            self.sink.error("E0204", f"'{parts[0]}' is an actor, not a value", node.span,
                            f"use one of its signals, e.g. `{parts[0]}.speed`")
            return None, None
        known = sorted(self.scope.params)
        notes = [f"parameters in scope: {', '.join(known)}"] if known else []
        if len(parts) >= 2:
            notes = [f"actors: {', '.join(sorted(self.scope.actors))}"]
        self.sink.error("E0101", f"unknown name '{node.dotted}'", node.span, *notes)
        return None, None

    def _Str(self, node: ast.Str):
        self.sink.error("E0204", "a string is not allowed here", node.span)
        return None, None

    def _ListExpr(self, node: ast.ListExpr):
        self.sink.error("E0204", "a list is not allowed here", node.span)
        return None, None

    def _signal(self, node, fn: str, args: tuple[str, ...]):
        cls = SIGNALS.get(fn)
        if cls is None:
            self.sink.error("E0101", f"unknown signal '{fn}'", node.span,
                            f"signals: {', '.join(SIGNALS.names())}")
            return None, None
        if not self.scope.allow_signals:
            self.sink.error("E0204", f"signal '{fn}' cannot be used here: only parameters and constants",
                            node.span)
            return None, None
        if len(args) != len(cls.args):
            self.sink.error("E0204", f"'{fn}' takes {len(cls.args)} argument(s), got {len(args)}", node.span)
            return None, None
        pools = {"actor": self.scope.actors, "node": self.scope.nodes, "step": self.scope.steps,
                 "light": self.scope.lights, "variable": self.scope.variables}
        for kind, arg in zip(cls.args, args):
            pool = pools[kind]
            if arg not in pool:
                what = "traffic-light controller" if kind == "light" else kind
                known = f"{what}s: {', '.join(sorted(pool))}" if pool else (
                    "no step is named: name one with a label, `brake_hard: at 3 s behavior brake`"
                    if kind == "step" else "traffic-light controllers: (none; declare one in `lights { }`)"
                    if kind == "light" else "variables: (none; declare one in `variables { }`)"
                    if kind == "variable" else f"no {kind}s")
                self.sink.error("E0405" if kind == "light" else "E0101", f"unknown {what} '{arg}' in {fn}(...)",
                                node.span, known)
                return None, None
        signal = E.Signal(name=f"{fn}({','.join(args)})")
        if cls.boolean:
            # A state signal (`ended(...)`: +1 holds, -1 not) is a formula: `> 0` makes it one
            # for the STL evaluator, robustness ±1 like `true`/`false`.
            return E.Binary(op=">", left=signal, right=E.Num(value=0.0)), BOOL
        return signal, ("num", cls.dim)

    def _CallExpr(self, node: ast.CallExpr):
        if node.fn in ARITH_FUNCS:
            lowered = [self.lower(a) for a in node.args]
            if any(e is None for e, _ in lowered):
                return None, None
            if not lowered or (node.fn in ("abs", "sqrt") and len(lowered) != 1):
                self.sink.error("E0204", f"wrong number of arguments to {node.fn}()", node.span)
                return None, None
            dims = {ty[1] for _, ty in lowered}
            if any(ty[0] != "num" for _, ty in lowered) or len(dims) != 1:
                self.sink.error("E0201", f"arguments of {node.fn}() must be numbers of one dimension",
                                node.span)
                return None, None
            dim = dims.pop()
            if node.fn == "sqrt":
                dim = Dim(dim.length // 2, dim.time // 2, dim.mass // 2, dim.angle // 2)
            return E.Call(fn=node.fn, args=tuple(e for e, _ in lowered)), ("num", dim)
        args = []
        cls = SIGNALS.get(node.fn)
        step_args = cls is not None and "step" in cls.args
        for a in node.args:
            if step_args and isinstance(a, ast.Ref) and len(a.parts) == 2:
                args.append(a.dotted)  # a named step: `lead.brake_hard`
                continue
            if not isinstance(a, ast.Ref) or len(a.parts) != 1:
                # `not eventually (...)`: a temporal operator is read as a name where it cannot stand.
                hint = ([f"`{node.fn}` starts a formula only at the top, after `implies` or in parentheses: "
                         f"`not ({node.fn} ...)`"] if node.fn in ("always", "eventually") else [])
                if step_args:
                    hint = ["name a step as `actor.label`, e.g. `ended(lead.brake_hard)`"]
                self.sink.error("E0204", f"arguments of {node.fn}() are "
                                f"{'step' if step_args else 'actor or node'} names", a.span, *hint)
                return None, None
            args.append(a.parts[0])
        return self._signal(node, node.fn, tuple(args))

    # ---- operators
    def _UnaryExpr(self, node: ast.UnaryExpr):
        arg, ty = self.lower(node.arg)
        if arg is None:
            return None, None
        if node.op == "not":
            if ty != BOOL:
                self.sink.error("E0203", "'not' needs a boolean formula", node.arg.span)
                return None, None
            return E.Unary(op="not", arg=arg), BOOL
        if ty[0] != "num":
            self.sink.error("E0203", "'-' needs a number", node.arg.span)
            return None, None
        return E.Unary(op="neg", arg=arg), ty

    def _BinaryExpr(self, node: ast.BinaryExpr):
        left, lty = self.lower(node.left)
        right, rty = self.lower(node.right)
        if left is None or right is None:
            return None, None
        op = node.op
        if op in E.BOOL_OPS:
            for side, ty in ((node.left, lty), (node.right, rty)):
                if ty != BOOL:
                    self.sink.error("E0203", f"'{op}' needs boolean formulas on both sides", side.span)
                    return None, None
            return E.Binary(op=op, left=left, right=right), BOOL
        if lty[0] != "num" or rty[0] != "num":
            bad = node.left if lty[0] != "num" else node.right
            self.sink.error("E0203", f"'{op}' needs numbers, found a boolean formula", bad.span)
            return None, None
        if op in ("*", "/"):
            dim = lty[1] * rty[1] if op == "*" else lty[1] / rty[1]
            return E.Binary(op=op, left=left, right=right), ("num", dim)
        if lty[1] != rty[1]:
            self.sink.error("E0201", f"cannot {'compare' if op in E.COMPARE_OPS else 'combine'} "
                            f"a {units.dim_name(lty[1])} with a {units.dim_name(rty[1])}", node.span,
                            label=f"{units.dim_name(lty[1])} {op} {units.dim_name(rty[1])}")
            return None, None
        if op in E.COMPARE_OPS:
            return E.Binary(op=op, left=left, right=right), BOOL
        return E.Binary(op=op, left=left, right=right), lty

    def window(self, window: ast.Window | None):
        """Lower a time window to (lo_s, hi_s): each bound a finite, non-negative constant [s],
        or an expression over parameters that each run resolves (`during [0 s, t_end]`; its
        values are checked over the sweep by rules/oracles.py). (None, None) after a diagnostic."""
        if window is None:
            return 0.0, None
        lo = self.lower_value(window.lo, units.TIME, "a window bound") if window.lo is not None else E.Num(value=0.0)
        hi = self.lower_value(window.hi, units.TIME, "a window bound") if window.hi is not None else None
        if lo is None or (window.hi is not None and hi is None):
            return None, None
        bounds = []
        for bound in (lo, hi):
            if bound is None or E.params_used(bound):
                bounds.append(bound)
                continue
            value = E.eval_param_expr(bound, {})
            if not (math.isfinite(value) and value >= 0.0):
                self.sink.error("E0301", "a window bound must be a finite time >= 0 s", window.span,
                                "windows are relative to the current instant: `within 5 s`, "
                                "`during [2 s, 5 s]`")
                return None, None
            bounds.append(value)
        lo, hi = bounds
        if isinstance(lo, float) and isinstance(hi, float) and hi < lo:
            self.sink.error("E0303", "the window ends before it starts", window.span)
            return None, None
        return lo, hi

    def _no_time(self, node, op: str) -> bool:
        """Where only parameters may appear (constraints, values) there is no time to range over."""
        if self.scope.allow_signals:
            return False
        self.sink.error("E0204", f"temporal operator '{op}' cannot be used here: only parameters and constants",
                        node.span, "only `expect` formulas and `when` triggers range over time; a constraint is "
                        "checked once per sampled assignment")
        return True

    def _TemporalExpr(self, node: ast.TemporalExpr):
        if self._no_time(node, node.op):
            return None, None
        arg = self.lower_formula(node.arg, f"the operand of '{node.op}'")
        lo, hi = self.window(node.window)
        if arg is None or lo is None:
            return None, None
        return E.Temporal(op=node.op, lo_s=lo, hi_s=hi, arg=arg), BOOL

    def _UntilExpr(self, node: ast.UntilExpr):
        if self._no_time(node, "until"):
            return None, None
        left = self.lower_formula(node.left, "the left side of 'until'")
        right = self.lower_formula(node.right, "the right side of 'until'")
        lo, hi = self.window(node.window)
        if left is None or right is None or lo is None:
            return None, None
        return E.Until(lo_s=lo, hi_s=hi, left=left, right=right), BOOL


def value_range(expr, ranges: dict[str, tuple[float, float]]) -> tuple[float, float] | None:
    """Bounds of an arithmetic expression when each parameter ranges over `ranges`
    (interval arithmetic: sound, possibly wider than the true range). None if unknown."""
    try:
        lo, hi = _interval(expr, ranges)
    except (KeyError, TypeError, ValueError, ZeroDivisionError, OverflowError):
        return None
    if math.isnan(lo) or math.isnan(hi):
        return None
    return lo, hi


def comparisons(constraints):
    """The comparisons each constraint holds for sure: itself, or the sides of its `and`s."""
    todo = list(constraints)
    while todo:
        c = todo.pop()
        if isinstance(c, E.Binary) and c.op == "and":
            todo += [c.left, c.right]
        elif isinstance(c, E.Binary) and c.op in E.COMPARE_OPS:
            yield c


_FLIPPED = {"<": ">", "<=": ">=", ">": "<", ">=": "<=", "==": "=="}


def narrowed_ranges(ranges: dict[str, tuple[float, float]], constraints) -> dict[str, tuple[float, float]]:
    """`ranges` narrowed by the constraints (`assume`) that bound one parameter by a
    constant range: `t_s <= 9 s`, `v > 2 * 5 m/s`, the sides of an `and`. Every run
    meets every constraint (a sample that breaks one is drawn again, a grid cell that
    breaks one runs nothing), so its values lie in the narrowed ranges; a strict bound
    narrows as its closure (sound, possibly wider). Constraints that bound none, or
    that would leave a range empty (reported as never holding elsewhere), narrow nothing."""
    out = dict(ranges)
    for c in comparisons(constraints):
        if c.op not in _FLIPPED:
            continue
        op, param, bound = c.op, c.left, c.right
        if not isinstance(param, E.Param):
            op, param, bound = _FLIPPED[op], c.right, c.left
        if not isinstance(param, E.Param) or param.name not in out or E.params_used(bound):
            continue
        got = value_range(bound, {})
        if got is None:
            continue
        lo, hi = out[param.name]
        if op in ("<", "<=", "=="):
            hi = min(hi, got[1])
        if op in (">", ">=", "=="):
            lo = max(lo, got[0])
        if lo <= hi:
            out[param.name] = (lo, hi)
    return out


def _interval(expr, ranges):
    match expr:
        case E.Num(value=v):
            return v, v
        case E.Param(name=n):
            return ranges[n]
        case E.Unary(op="neg", arg=a):
            lo, hi = _interval(a, ranges)
            return -hi, -lo
        case E.Call(fn="abs", args=(a,)):
            lo, hi = _interval(a, ranges)
            if lo >= 0:
                return lo, hi
            if hi <= 0:
                return -hi, -lo
            return 0.0, max(-lo, hi)
        case E.Call(fn="sqrt", args=(a,)):
            lo, hi = _interval(a, ranges)
            return math.sqrt(max(lo, 0.0)), math.sqrt(max(hi, 0.0))
        case E.Call(fn="min", args=args):
            ivs = [_interval(a, ranges) for a in args]
            return min(i[0] for i in ivs), min(i[1] for i in ivs)
        case E.Call(fn="max", args=args):
            ivs = [_interval(a, ranges) for a in args]
            return max(i[0] for i in ivs), max(i[1] for i in ivs)
        case E.Binary(op=op, left=l, right=r) if op in ("+", "-", "*", "/"):
            a, b = _interval(l, ranges), _interval(r, ranges)
            if op == "+":
                return a[0] + b[0], a[1] + b[1]
            if op == "-":
                return a[0] - b[1], a[1] - b[0]
            if op == "/":
                if b[0] <= 0.0 <= b[1]:
                    raise ZeroDivisionError
                b = (1.0 / b[1], 1.0 / b[0])
            products = [x * y for x in a for y in b]
            return min(products), max(products)
    raise TypeError(f"no interval for {expr!r}")
