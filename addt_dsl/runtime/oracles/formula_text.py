"""Oracle formulas as text: a self-contained parser and the matching printer.

Same surface syntax as the `.addt` DSL's oracles, e.g.
    always during [2 s, 5 s] ttc(ego, lead) > 1 s
    eventually within 40 s ego.s > 900 m
    lane_offset(ego) < 0.5 m until within 5 s ego.speed < 30 km/h

Precedence, loosest first: `always`/`eventually` (operand extends as far right as
possible), `implies` (right-assoc), `or`, `and`, `until` (right-assoc), `not`,
comparison (non-chaining), `+ -`, `* /`, unary `-`. A `-` written right before a number
is part of the number literal (`-3` is Num(-3), `-(3)` is neg(Num(3))), which is what
lets `format_formula` round-trip every tree exactly: parse(format(e)) == e.
Numbers take an optional unit and are converted to SI; window bounds need a time unit.
"""

from __future__ import annotations

import math
import re
from collections.abc import Collection
from dataclasses import dataclass

from addt_dsl.expr import Binary, Call, Expr, Num, Param, Signal, Temporal, Unary, Until
from addt_dsl.units import TIME, UNITS, number_literal, to_si

__all__ = ["FormulaSyntaxError", "format_formula", "parse_formula"]


class FormulaSyntaxError(ValueError):
    def __init__(self, message: str, column: int, text: str = ""):
        super().__init__(f"{message} (column {column})")
        self.message = message
        self.column = column  # 1-based
        self.text = text


KEYWORDS = frozenset(("always", "eventually", "until", "within", "during", "after",
                      "not", "and", "or", "implies"))
FUNCTIONS = frozenset(("abs", "min", "max", "sqrt"))

# --- lexer ------------------------------------------------------------------------------

_NAME = r"[A-Za-z_][A-Za-z0-9_]*(?:\.[A-Za-z_][A-Za-z0-9_]*)*"
_NUMBER = r"(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?"
_TOKEN = re.compile(rf"""
    (?P<ws>\s+)
  | (?P<num>{_NUMBER})
  | (?P<name>{_NAME})
  | (?P<op><=|>=|==|!=|[<>+\-*/()\[\],])
""", re.VERBOSE)
# A unit directly follows a number; `/m` is left out because it would swallow division.
_UNIT_SYMBOLS = sorted((u for u in UNITS if not u.startswith("/")), key=len, reverse=True)
_AFTER_UNIT = re.compile(r"[A-Za-z0-9_.(^]")


@dataclass(frozen=True, slots=True)
class _Tok:
    kind: str  # num | name | op | eof
    text: str
    col: int   # 1-based
    value: float = 0.0
    unit: str | None = None


def _unit_at(text: str, pos: int) -> str | None:
    for sym in _UNIT_SYMBOLS:
        end = pos + len(sym)
        if text.startswith(sym, pos) and not _AFTER_UNIT.match(text, end):
            return sym
    return None


def _lex(text: str) -> list[_Tok]:
    toks: list[_Tok] = []
    pos = 0
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if not m:
            raise FormulaSyntaxError(f"unexpected character {text[pos]!r}", pos + 1, text)
        kind = m.lastgroup
        if kind == "num":
            start, pos = pos, m.end()
            unit_pos = len(text) - len(text[pos:].lstrip())
            unit = _unit_at(text, unit_pos)
            if unit is not None:
                pos = unit_pos + len(unit)
            toks.append(_Tok("num", text[start:pos], start + 1, float(m.group()), unit))
            continue
        if kind != "ws":
            toks.append(_Tok(kind, m.group(), pos + 1))
        pos = m.end()
    toks.append(_Tok("eof", "", len(text) + 1))
    return toks


# --- parser (recursive descent, one function per precedence level) ---------------------

_COMPARE = ("<", "<=", ">", ">=", "==", "!=")


class _Parser:
    def __init__(self, text: str, params: Collection[str]):
        self.text = text
        self.toks = _lex(text)
        self.i = 0
        self.params = params

    # helpers
    @property
    def tok(self) -> _Tok:
        return self.toks[self.i]

    def at(self, *texts: str) -> bool:
        return self.tok.kind in ("op", "name") and self.tok.text in texts

    def take(self) -> _Tok:
        tok = self.tok
        self.i += 1
        return tok

    def expect(self, text: str) -> _Tok:
        if not self.at(text):
            self.fail(f"expected '{text}'")
        return self.take()

    def fail(self, message: str, tok: _Tok | None = None):
        tok = tok or self.tok
        found = "end of formula" if tok.kind == "eof" else repr(tok.text)
        raise FormulaSyntaxError(f"{message}, found {found}", tok.col, self.text)

    # grammar
    def formula(self) -> Expr:
        left = self.disjunction()
        if self.at("implies"):
            self.take()
            return Binary(op="implies", left=left, right=self.formula())
        return left

    def disjunction(self) -> Expr:
        return self._chain(self.conjunction, ("or",))

    def conjunction(self) -> Expr:
        return self._chain(self.until, ("and",))

    def until(self) -> Expr:
        left = self.negation()
        if not self.at("until"):
            return left
        self.take()
        lo, hi = self.interval()
        return Until(lo_s=lo, hi_s=hi, left=left, right=self.until())

    def negation(self) -> Expr:
        if self.at("not"):
            self.take()
            return Unary(op="not", arg=self.negation())
        if self.at("always", "eventually"):
            op = self.take().text
            lo, hi = self.interval()
            return Temporal(op=op, lo_s=lo, hi_s=hi, arg=self.formula())
        return self.comparison()

    def comparison(self) -> Expr:
        left = self.sum()
        if not self.at(*_COMPARE):
            return left
        op = self.take().text
        right = self.sum()
        if self.at(*_COMPARE):
            self.fail("comparisons don't chain: add parentheses")
        return Binary(op=op, left=left, right=right)

    def sum(self) -> Expr:
        return self._chain(self.product, ("+", "-"))

    def product(self) -> Expr:
        return self._chain(self.unary, ("*", "/"))

    def unary(self) -> Expr:
        if not self.at("-"):
            return self.primary()
        self.take()
        if self.tok.kind == "num":  # `-3` is a literal, `-(3)` a negation
            return Num(value=-self.number())
        return Unary(op="neg", arg=self.unary())

    def primary(self) -> Expr:
        tok = self.tok
        if tok.kind == "num":
            return Num(value=self.number())
        if self.at("("):
            self.take()
            inner = self.formula()
            self.expect(")")
            return inner
        if tok.kind == "name" and tok.text not in KEYWORDS:
            self.take()
            if self.at("("):
                return self.call(tok)
            return Param(name=tok.text) if tok.text in self.params else Signal(name=tok.text)
        self.fail("expected a number, a signal or '('")

    def call(self, name: _Tok) -> Expr:
        self.expect("(")
        if name.text in FUNCTIONS:
            args = [self.formula()]
            while self.at(","):
                self.take()
                args.append(self.formula())
            self.expect(")")
            if name.text in ("abs", "sqrt") and len(args) != 1:
                self.fail(f"{name.text}() takes one argument", name)
            return Call(fn=name.text, args=tuple(args))
        # Any other call names a signal: `ttc(ego, lead)` is the signal "ttc(ego,lead)".
        args = [self.signal_arg()]
        while self.at(","):
            self.take()
            args.append(self.signal_arg())
        self.expect(")")
        return Signal(name=f"{name.text}({','.join(args)})")

    def signal_arg(self) -> str:
        tok = self.tok
        if (tok.kind == "name" and tok.text not in KEYWORDS) or (tok.kind == "num" and tok.unit is None):
            return self.take().text
        self.fail("expected a name as signal argument")

    def number(self) -> float:
        tok = self.take()
        return to_si(tok.value, tok.unit)[0]

    def interval(self) -> tuple[float, float | None]:
        if self.at("within"):
            self.take()
            return 0.0, self.duration()
        if self.at("after"):
            self.take()
            return self.duration(), None
        if self.at("during"):
            self.take()
            open_tok = self.expect("[")
            lo = self.duration()
            self.expect(",")
            hi = self.duration()
            self.expect("]")
            if not hi >= lo:
                raise FormulaSyntaxError(f"empty interval [{lo} s, {hi} s]", open_tok.col, self.text)
            return lo, hi
        return 0.0, None

    def duration(self) -> float:
        tok = self.tok
        if tok.kind != "num":
            self.fail("expected a duration such as '5 s'")
        value, dim = to_si(tok.value, tok.unit)
        if dim != TIME:
            self.fail("a window bound needs a time unit (s, ms, min)")
        self.take()
        return value

    def _chain(self, operand, ops: tuple[str, ...]) -> Expr:
        left = operand()
        while self.at(*ops):
            op = self.take().text
            left = Binary(op=op, left=left, right=operand())
        return left


def parse_formula(text: str, params: Collection[str] = ()) -> Expr:
    """Parse a formula; names in `params` become `Param`, every other name a `Signal`."""
    parser = _Parser(text, frozenset(params))
    expr = parser.formula()
    if parser.tok.kind != "eof":
        parser.fail("unexpected text after the formula")
    return expr


# --- printer ----------------------------------------------------------------------------

# Binding strength, loosest first (the parser's levels).
_TEMPORAL, _IMPLIES, _OR, _AND, _UNTIL, _NOT, _CMP, _SUM, _PROD, _NEG, _ATOM = range(11)
_BINARY_LEVEL = {"implies": _IMPLIES, "or": _OR, "and": _AND, "+": _SUM, "-": _SUM,
                 "*": _PROD, "/": _PROD, **{op: _CMP for op in _COMPARE}}
_ARG = rf"(?:{_NAME}|{_NUMBER})"
_PRINTABLE_SIGNAL = re.compile(rf"{_NAME}(?:\({_ARG}(?:,{_ARG})*\))?")


def format_formula(expr: Expr) -> str:
    """Print a tree in the surface syntax (numbers in SI, window bounds in seconds)."""
    return _fmt(expr, _TEMPORAL, True)


def _level(expr: Expr) -> int:
    match expr:
        case Temporal():
            return _TEMPORAL
        case Until():
            return _UNTIL
        case Binary(op=op):
            return _BINARY_LEVEL[op]
        case Unary(op="not"):
            return _NOT
        case Unary(op="neg"):
            return _NEG
        case Num(value=v) if math.copysign(1, v) < 0:  # printed with its minus sign
            return _NEG
    return _ATOM


def _fmt(expr: Expr, need: int, tail: bool) -> str:
    """`need`: the loosest level allowed here; `tail`: nothing follows in the output, so
    a prefix temporal operator (which extends to the far right) needs no parentheses."""
    level = _level(expr)
    if level == _TEMPORAL:  # a prefix operator: fine wherever `not` is, if nothing follows
        paren = need > _NOT or not tail
    else:
        paren = level < need
    if paren:
        return f"({_render(expr, True)})"
    return _render(expr, tail)


def _render(expr: Expr, tail: bool) -> str:
    match expr:
        case Num(value=v):
            return _number(v)
        case Signal(name=name):
            if not _PRINTABLE_SIGNAL.fullmatch(name) or name in KEYWORDS or _is_function_call(name):
                raise ValueError(f"signal name {name!r} has no surface syntax")
            return name
        case Param(name=name):
            return name
        case Call(fn=fn, args=args):
            return f"{fn}({', '.join(_fmt(a, _TEMPORAL, True) for a in args)})"
        case Unary(op="neg", arg=Num() as num):
            return f"-({_render(num, True)})"  # `-3` would read back as the literal
        case Unary(op="neg", arg=a):
            return "-" + _fmt(a, _NEG, tail)
        case Unary(op="not", arg=a):
            return "not " + _fmt(a, _NOT, tail)
        case Binary(op="implies", left=l, right=r):
            return f"{_fmt(l, _IMPLIES + 1, False)} implies {_fmt(r, _IMPLIES, tail)}"
        case Binary(op=op, left=l, right=r):
            lvl = _BINARY_LEVEL[op]
            left_need = lvl + 1 if lvl == _CMP else lvl
            return f"{_fmt(l, left_need, False)} {op} {_fmt(r, lvl + 1, tail)}"
        case Until(lo_s=lo, hi_s=hi, left=l, right=r):
            return (f"{_fmt(l, _UNTIL + 1, False)} until{_interval(lo, hi)} "
                    f"{_fmt(r, _UNTIL, tail)}")
        case Temporal(op=op, lo_s=lo, hi_s=hi, arg=a):
            return f"{op}{_interval(lo, hi)} {_fmt(a, _TEMPORAL, tail)}"
    raise TypeError(f"not an expression node: {expr!r}")


def _is_function_call(name: str) -> bool:
    return "(" in name and name.split("(", 1)[0] in FUNCTIONS


def _interval(lo: float, hi: float | None) -> str:
    if hi is None:
        return "" if lo == 0 else f" after {_seconds(lo)}"
    if lo == 0:
        return f" within {_seconds(hi)}"
    return f" during [{_seconds(lo)}, {_seconds(hi)}]"


def _seconds(v: float) -> str:
    return f"{_number(v)} s"


_number = number_literal
