"""Parameters: `$name` references, `${...}` arithmetic (its limits: docs/limits.md), attribute
values as numbers or parameter expressions; the expression helpers the translation shares."""

import ast
import math
import operator
import re

from pydantic import TypeAdapter

from addt_dsl import expr as E
from addt_dsl import units
from addt_dsl.expr import eval_param_expr
from addt_dsl.interop.openscenario.xml import Stop

MAX_EXPRESSION_CHARS = 10_000  # a `${...}` expression's length (docs/limits.md)
NAME_RE = re.compile(r"[A-Za-z_]\w*")
EXPR = TypeAdapter(E.Expr)


# ---------------------------------------------------------------- values

_BINOPS = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul, ast.Div: operator.truediv,
           ast.Pow: operator.pow, ast.Mod: operator.mod}


def arith(node) -> float:
    """A `${...}` expression: numbers, + - * / % **, unary minus, parentheses."""
    if isinstance(node, ast.Expression):
        return arith(node.body)
    if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) and not isinstance(node.value, bool):
        return float(node.value)
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
        v = arith(node.operand)
        return -v if isinstance(node.op, ast.USub) else v
    if isinstance(node, ast.BinOp) and type(node.op) in _BINOPS:
        left, right = arith(node.left), arith(node.right)
        if isinstance(node.op, ast.Pow) and abs(right) > 64:
            raise ValueError("exponent too large")
        return float(_BINOPS[type(node.op)](left, right))
    raise ValueError("unsupported expression")


def is_number(text: str) -> bool:
    try:
        return math.isfinite(float(text))
    except ValueError:
        return False


def plus_expr(a, b):
    if isinstance(a, E.Num) and isinstance(b, E.Num):
        return E.Num(value=a.value + b.value)
    if isinstance(b, E.Num) and b.value == 0.0:
        return a
    return E.Binary(op="+", left=a, right=b)


def all_of(parts):
    out = parts[0]
    for p in parts[1:]:
        out = E.Binary(op="and", left=out, right=p)
    return out


def any_of(parts):
    out = parts[0]
    for p in parts[1:]:
        out = E.Binary(op="or", left=out, right=p)
    return out


class Parameters:
    # -- attribute values

    def raw(self, el, attr: str, required: bool = True) -> str | None:
        value = el.get(attr)
        if value is None:
            if required:
                self.error(el, f"<{el.tag}> has no attribute '{attr}'")
                raise Stop
            return None
        try:
            return self.resolve(value)
        except KeyError as exc:
            self.error(el, f"unknown parameter '${exc.args[0]}' in {attr}")
            raise Stop from None
        except (SyntaxError, ValueError, ArithmeticError, RecursionError, MemoryError):
            self.error(el, f"cannot evaluate {attr}=\"{value[:80]}\"")
            raise Stop from None

    def resolve(self, value: str, depth: int = 0) -> str:
        """`$name` and `${expression}` resolved (parameters may refer to parameters). Each
        parameter's value is resolved once (a file whose parameters each refer to the one
        before many times would otherwise take exponential time)."""
        if depth > 16:
            raise ValueError("parameters refer to each other too deeply")
        if value.startswith("${") and value.endswith("}"):
            if len(value) > MAX_EXPRESSION_CHARS:
                raise ValueError(f"an expression of {len(value)} characters (at most {MAX_EXPRESSION_CHARS})")
            body = re.sub(r"\$([A-Za-z_]\w*)", lambda m: self.resolve("$" + m.group(1), depth + 1), value[2:-1])
            return repr(arith(ast.parse(body, mode="eval")))
        if value.startswith("$"):
            if value[1:] not in self.params:
                raise KeyError(value[1:])
            raw = self.params[value[1:]][1]
            key = (value[1:], raw)
            if key not in self.resolved:
                self.resolved[key] = self.resolve(raw, depth + 1)
            return self.resolved[key]
        return value

    def number(self, el, attr: str, dim=units.DIMENSIONLESS, default: float | None = None,
               keep: bool = True) -> E.Expr:
        """The attribute as an expression: a parameter reference (`$name`) stays a parameter."""
        text = self.raw(el, attr, required=default is None)
        if text is None:
            return E.Num(value=float(default))
        try:
            value = float(text)
        except ValueError:
            self.error(el, f"{attr}=\"{text[:40]}\" is not a number")
            raise Stop from None
        if not math.isfinite(value):
            self.error(el, f"{attr}=\"{text[:40]}\" is not finite")
            raise Stop
        ref = el.get(attr, "")
        plain = is_number(self.params.get(ref[1:], ("", ""))[1])
        if keep and plain and ref.startswith("$") and not ref.startswith("${") and NAME_RE.fullmatch(ref[1:]):
            name = ref[1:]
            known = self.param_dims.get(name, dim)
            self.param_dims[name] = dim if known == dim else None
            return E.Param(name=name)
        return E.Num(value=value)

    def value(self, el, attr: str, dim=units.DIMENSIONLESS, default: float | None = None) -> float:
        return float(eval_param_expr(self.number(el, attr, dim, default, keep=False), {}))

    def param_values(self) -> dict[str, float]:
        out = {}
        for name, (_, raw) in self.params.items():
            try:
                out[name] = float(self.resolve(raw))
            except (KeyError, SyntaxError, ValueError, ArithmeticError, RecursionError, MemoryError):
                pass
        return out
