"""Expression and formula printing: `Expr` trees → `.addt` text with units.

The plan stores SI numbers without units, so numbers are printed with the canonical
unit of the dimension their context requires: a setting's `ParamSpec.dim`, a parameter's
dimension, or the dimension inferred from the signals and parameters an expression
combines (`SIGNALS` registry). Every canonical unit has the factor 1, so a printed
number reads back bit for bit; angles use `deg` where that is exact too. Parentheses
follow the binding levels of the DSL grammar, so the compiler reads the text back to the
same tree (`compiler.formula.parse_formula` for a formula on its own). This is the one
printer of formulas (oracles, constraints, trigger conditions, reports).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable

from addt_dsl import expr as E
from addt_dsl import units
from addt_dsl.plan import LIGHT_STATES
from addt_dsl.registry import SIGNALS
from addt_dsl.units import Dim

__all__ = ["BOOL", "PrinterError", "dim_of_name", "format_const", "format_expr", "format_quantity", "string_literal"]


class PrinterError(ValueError):
    """The plan holds something the surface syntax cannot express."""


# ---------------------------------------------------------------- numbers and quantities

# Units tried before the canonical one, when they read back exactly (nicer to read).
PREFERRED_UNITS: dict[Dim, tuple[str, ...]] = {units.ANGLE: ("deg",), units.ANGULAR_RATE: ("deg/s",)}


def _number(value: float) -> str:
    try:
        return units.number_literal(value)
    except ValueError as exc:
        raise PrinterError(str(exc)) from None


def _noisy(text: str) -> bool:
    return units.significant_digits(text) > units.NOISE_DIGITS


def _exact_in(value: float, unit: units.Unit) -> str | None:
    """`value` [SI] as a short literal in `unit` that reads back bit for bit, or None."""
    scaled = value / unit.factor
    if not math.isfinite(scaled):
        return None
    text = units.number_literal(float(f"{scaled:.{units.NOISE_DIGITS}g}"))
    return text if float(text) * unit.factor == value else None


def format_quantity(value: float, dim: Dim) -> str:
    """An SI value as a literal of dimension `dim` that reads back bit for bit. Where the
    canonical unit's number is float noise (`13.88888888888889 m/s`), a unit of the dimension
    that writes it short and exactly (`50 km/h`)."""
    value = float(value)
    for symbol in PREFERRED_UNITS.get(dim, ()):
        unit = units.UNITS[symbol]
        scaled = value / unit.factor
        text = _number(scaled)
        if math.isfinite(scaled) and len(text) <= 8 and float(text) * unit.factor == value:
            return f"{text} {symbol}"
    if dim == units.DIMENSIONLESS:
        return _number(value)
    unit = units.CANONICAL_UNIT.get(dim)
    if unit is None:
        raise PrinterError(f"no unit for a {units.dim_name(dim)} literal")
    text = _number(value)
    if _noisy(text) and math.isfinite(value):
        for other in units.UNITS.values():
            if other.dim == dim and other.symbol != unit and (short := _exact_in(value, other)) is not None:
                return f"{short} {other.symbol}"
    return f"{text} {unit}"


def format_const(value: float, dim: Dim) -> str:
    """A constant that the compiler folds (parameter defaults, list items): compound
    dimensions without a unit of their own are written as `v m * 1 s` (exact: × 1.0)."""
    if dim == units.DIMENSIONLESS or dim in units.CANONICAL_UNIT:
        return format_quantity(value, dim)
    factors = [("*" if exp > 0 else "/", units.CANONICAL_UNIT[base])
               for base, exp in ((units.LENGTH, dim.length), (units.TIME, dim.time), (units.MASS, dim.mass),
                                 (units.ANGLE, dim.angle)) for _ in range(abs(exp))]
    factors.sort(key=lambda f: f[0] != "*")  # a unit with a positive power goes on the number
    text = _number(value)
    if factors[0][0] == "*":
        text += f" {factors.pop(0)[1]}"
    return " ".join([text, *(f"{op} 1 {symbol}" for op, symbol in factors)])


def dim_of_name(name: str) -> Dim:
    try:
        return units.dim_from_name(name)
    except ValueError:
        raise PrinterError(f"unknown dimension {name!r}") from None


def string_literal(text: str) -> str:
    if not re.search(r'["\\\x00-\x1f\x7f]', text):
        return f'"{text}"'
    # The parser decodes escapes with `unicode_escape`, so escape non-ASCII too.
    return '"' + text.encode("unicode_escape").decode("ascii").replace('"', '\\"') + '"'


# ---------------------------------------------------------------- expressions

# Binding levels of the DSL grammar (addt.lark), loosest first. A node printed in a slot
# that needs a tighter level gets parentheses.
TEMPORAL, IMPLIES, OR, AND, UNTIL, NOT, CMP, SUM, PROD, NEG, ATOM = range(11)
_BINARY = {  # op: (level, left slot, right slot)
    "implies": (IMPLIES, OR, TEMPORAL),
    "or": (OR, OR, AND),
    "and": (AND, AND, UNTIL),
    **{op: (CMP, SUM, SUM) for op in E.COMPARE_OPS},
    "+": (SUM, SUM, PROD), "-": (SUM, SUM, PROD),
    "*": (PROD, PROD, NEG), "/": (PROD, PROD, NEG),
}
BOOL = "bool"  # the expected "dimension" of a formula


class ExprPrinter:
    """Prints `Expr` trees with units, inferring each number's dimension from context."""

    def __init__(self, param_dims: dict[str, Dim]):
        self.param_dims = param_dims

    # -- dimension inference: None means "free" (only numbers: any dimension fits)
    def dim(self, e) -> Dim | None:
        match e:
            case E.Num():
                return None
            case E.Param(name=n):
                if n not in self.param_dims:
                    raise PrinterError(f"unknown parameter {n!r}")
                return self.param_dims[n]
            case E.Signal(name=n):
                cls = SIGNALS.get(n.partition("(")[0])
                if cls is None:
                    raise PrinterError(f"unknown signal {n!r}")
                return cls.dim
            case E.Call(fn="sqrt", args=(a,)):
                d = self.dim(a)
                return None if d is None else Dim(d.length // 2, d.time // 2, d.mass // 2, d.angle // 2)
            case E.Call(args=args):
                return next((d for d in map(self.dim, args) if d is not None), None)
            case E.Unary(op="neg", arg=a):
                return self.dim(a)
            case E.Binary(op="+" | "-", left=l, right=r):
                d = self.dim(l)
                return d if d is not None else self.dim(r)
            case E.Binary(op="*" | "/", left=l, right=r):
                dl, dr = self.dim(l), self.dim(r)
                if dl is None or dr is None:
                    return None
                return dl * dr if e.op == "*" else dl / dr
        raise PrinterError(f"not a value expression: {e!r}")

    def default_dim(self, e) -> Dim:
        """The dimension a free expression most naturally has: numbers in products are
        plain factors (`2 * gap`), elsewhere they take their sibling's dimension."""
        d = self.dim(e)
        if d is not None:
            return d
        match e:
            case E.Binary(op="*" | "/", left=l, right=r):
                dl, dr = self.default_dim(l), self.default_dim(r)
                return dl * dr if e.op == "*" else dl / dr
            case E.Binary(left=l, right=r):
                return self.default_dim(r if _has_ref(r) and not _has_ref(l) else l)
            case E.Unary(arg=a):
                return self.default_dim(a)
            case E.Call(fn="sqrt", args=(a,)):
                d = self.default_dim(a)
                return Dim(d.length // 2, d.time // 2, d.mass // 2, d.angle // 2)
            case E.Call(args=args) if args:  # no arguments: printed as such, and the compiler says so
                return self.default_dim(next((a for a in args if _has_ref(a)), args[0]))
        return units.DIMENSIONLESS

    def comparison_dims(self, left, right) -> list[Dim]:
        """Dimensions to try for both sides of a comparison, most natural first."""
        for side in (left, right):
            d = self.dim(side)
            if d is not None:
                return [d]
        # Both sides are free: the side that names a signal or parameter decides, else any.
        first = right if _has_ref(right) and not _has_ref(left) else left
        out = []
        for d in (self.default_dim(first), self.default_dim(left), self.default_dim(right),
                  units.DIMENSIONLESS, *units.CANONICAL_UNIT):
            if d not in out:
                out.append(d)
        return out

    # -- printing: returns (text, level)
    def format(self, e, want, slot: int = TEMPORAL) -> str:
        text, level = _NODE_PRINTERS[type(e)](self, e, want)
        if level < slot:
            return f"({text})"
        return text

    def formula(self, e) -> str:
        return self.format(e, BOOL)

    def value(self, e, dim: Dim) -> str:
        return self.format(e, dim)


def _has_ref(e) -> bool:
    return any(isinstance(n, (E.Param, E.Signal)) for n in E.walk(e))


def _p_num(p: ExprPrinter, e: E.Num, want):
    if want == BOOL:
        if e.value not in (1.0, -1.0):
            raise PrinterError(f"{e.value!r} is not a truth value")
        return ("true" if e.value > 0 else "false"), ATOM
    text = format_quantity(e.value, want)
    return text, NEG if text.startswith("-") else ATOM


def _p_param(p, e: E.Param, want):
    return e.name, ATOM


def _p_signal(p, e: E.Signal, want):
    fn, _, rest = e.name.partition("(")
    args = [a for a in rest.rstrip(")").split(",") if a]
    if not re.fullmatch(r"[A-Za-z_]\w*", fn) or not all(re.fullmatch(r"[A-Za-z_]\w*", a) for a in args):
        raise PrinterError(f"signal {e.name!r} has no surface syntax")
    return f"{fn}({', '.join(args)})", ATOM


def _p_call(p: ExprPrinter, e: E.Call, want):
    if e.fn == "sqrt":
        d = p.dim(e.args[0])
        inner = d if d is not None else want * want
        return f"sqrt({p.format(e.args[0], inner)})", ATOM
    return f"{e.fn}({', '.join(p.format(a, want) for a in e.args)})", ATOM


def _p_unary(p: ExprPrinter, e: E.Unary, want):
    if e.op == "not":
        return "not " + p.format(e.arg, BOOL, NOT), NOT
    if isinstance(e.arg, E.Num):
        raise PrinterError("a negated number literal reads back as a negative literal")
    inner = p.format(e.arg, want, NEG)
    if inner.startswith("-"):
        inner = f"({inner})"
    return "-" + inner, NEG


def _p_binary(p: ExprPrinter, e: E.Binary, want):
    if _is_state(e):  # `ended(lead.brake_hard)`, lowered as `> 0` (compiler/exprs.py)
        fn, _, rest = e.left.name.partition("(")
        if not re.fullmatch(r"[A-Za-z_]\w*\.[A-Za-z_]\w*", rest.rstrip(")")):
            raise PrinterError(f"signal {e.left.name!r} has no surface syntax")
        return e.left.name, ATOM
    level, left_slot, right_slot = _BINARY[e.op]
    if e.op in E.BOOL_OPS:
        lw = rw = BOOL
    elif e.op in E.COMPARE_OPS:
        state = _light_state(e)
        if state is not None and state not in p.param_dims:  # `light(west) == red`: the state by its name
            return f"{p.format(e.left, units.DIMENSIONLESS, left_slot)} {e.op} {state}", level
        for dim in p.comparison_dims(e.left, e.right):
            try:
                return f"{p.format(e.left, dim, left_slot)} {e.op} {p.format(e.right, dim, right_slot)}", level
            except PrinterError:
                continue
        raise PrinterError("no dimension makes both sides of this comparison writable")
    elif e.op in ("+", "-"):
        lw = rw = want
    else:
        return _product(p, e, want, left_slot, right_slot), level
    return f"{p.format(e.left, lw, left_slot)} {e.op} {p.format(e.right, rw, right_slot)}", level


def _is_state(e: E.Binary) -> bool:
    if e.op != ">" or not isinstance(e.left, E.Signal) or e.right != E.Num(value=0.0):
        return False
    cls = SIGNALS.get(e.left.name.partition("(")[0])
    return cls is not None and cls.boolean


def _light_state(e: E.Binary) -> str | None:
    """The state name when `e` compares a traffic light's state with a state's code."""
    if isinstance(e.left, E.Signal) and e.left.name.startswith("light(") and isinstance(e.right, E.Num):
        return next((name for name, code in LIGHT_STATES.items() if code == e.right.value), None)
    return None


def _product(p: ExprPrinter, e: E.Binary, want: Dim, left_slot: int, right_slot: int) -> str:
    """`a * b` / `a / b` of dimension `want`: a free side takes what the other leaves;
    two free sides try the splits in turn (the left taking the whole dimension first)."""
    dl, dr = p.dim(e.left), p.dim(e.right)
    mul = e.op == "*"
    if dl is not None and dr is not None:
        splits = [(dl, dr)]
    elif dl is not None:
        splits = [(dl, want / dl if mul else dl / want)]
    elif dr is not None:
        splits = [(want / dr if mul else want * dr, dr)]
    else:
        splits = [(left, want / left if mul else left / want)
                  for left in (want, units.DIMENSIONLESS, *units.CANONICAL_UNIT)]
    for lw, rw in splits:
        try:
            return f"{p.format(e.left, lw, left_slot)} {e.op} {p.format(e.right, rw, right_slot)}"
        except PrinterError:
            continue
    raise PrinterError(f"cannot write `{e.op}` of dimension {units.dim_name(want)} with these literals")


def _window(p: ExprPrinter, lo, hi) -> tuple[str, bool]:
    """The window's text and whether a bound is an expression over parameters."""
    def bound(b) -> str:
        return format_quantity(b, units.TIME) if isinstance(b, float) else p.format(b, units.TIME, SUM)

    exprs = not isinstance(lo, float) or (hi is not None and not isinstance(hi, float))
    if hi is None:
        return ("" if lo == 0 else f" after {bound(lo)}"), exprs
    if lo == 0:
        return f" within {bound(hi)}", exprs
    return f" during [{bound(lo)}, {bound(hi)}]", exprs


def _after_window(window: tuple[str, bool], operand: str) -> str:
    """After `within T` / `after T` an operand starting with '-' or '(' would be read as
    part of the time bound (`within 5 s - x`): parenthesise it there, and a bound over
    parameters too (`within t_end (x)` would read as a call)."""
    text, exprs = window
    if text and not text.endswith("]") and operand[:1] in "-(":
        if exprs:
            keyword, _, bound = text.strip().partition(" ")
            text = f" {keyword} ({bound})"
        return f"{text} ({operand})"
    return f"{text} {operand}"


def _p_temporal(p: ExprPrinter, e: E.Temporal, want):
    window = _window(p, e.lo_s, e.hi_s)
    return f"{e.op}{_after_window(window, p.format(e.arg, BOOL, TEMPORAL))}", TEMPORAL


def _p_until(p: ExprPrinter, e: E.Until, want):
    window = _window(p, e.lo_s, e.hi_s)
    return (f"{p.format(e.left, BOOL, NOT)} until{_after_window(window, p.format(e.right, BOOL, NOT))}"), UNTIL


_NODE_PRINTERS: dict[type, Callable] = {
    E.Num: _p_num, E.Param: _p_param, E.Signal: _p_signal, E.Call: _p_call,
    E.Unary: _p_unary, E.Binary: _p_binary, E.Temporal: _p_temporal, E.Until: _p_until,
}


def format_expr(expr, want: Dim | str = BOOL, param_dims: dict[str, Dim] | None = None) -> str:
    """Print a value expression of dimension `want`, or a formula (`want="bool"`)."""
    return ExprPrinter(param_dims or {}).format(expr, want)
