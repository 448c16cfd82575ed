"""One formula on its own: `parse_formula("always ttc(ego, lead) > 1 s")` → `Expr`.

The same language as the oracles of a `.addt` file, read by the same code: a lark parser
of the same grammar started at its `expr` rule (`parser.parse_expression`), the same AST
builder and the same typing and lowering (`exprs.ExprLowering`: registered signals,
dimensions, units to SI). What a scenario rejects is rejected here, with the same
diagnostics, raised as a `FormulaError`. Print a tree back with
`addt_dsl.printer.format_expr`.

A formula on its own has no scenario around it, so any name may stand for an actor or a
stack node (`ttc(ego, lead)`, `latency(planner)`), parameters are given with their
dimensions, and trace signals may be named directly (`x`, for synthetic traces) when
given with theirs. The runtime never parses: it evaluates the `Expr` trees.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

from addt_dsl import expr as E
from addt_dsl.compiler import ast
from addt_dsl.compiler.exprs import ARITH_FUNCS, ExprLowering, Scope
from addt_dsl.compiler.parser import parse_expression
from addt_dsl.diagnostics import Diagnostic, DiagnosticSink, render_text
from addt_dsl.registry import SIGNALS
from addt_dsl.units import Dim

__all__ = ["FormulaError", "parse_formula"]

FORMULA_PATH = "<formula>"


class FormulaError(ValueError):
    """A formula that does not parse or type-check; `diagnostics` says where and why."""

    def __init__(self, text: str, diagnostics: list[Diagnostic]):
        first = diagnostics[0]
        self.text = text
        self.diagnostics = diagnostics
        self.code = first.code
        self.message = first.message
        self.column = first.span.col if first.span is not None else 1  # 1-based
        super().__init__(render_text(diagnostics, {FORMULA_PATH: text}))


def parse_formula(text: str, params: Mapping[str, Dim] | None = None,
                  signals: Mapping[str, Dim] | None = None) -> E.Expr:
    """The formula's tree (numbers in SI), or FormulaError. `params`: parameter names and
    dimensions it may use; `signals`: trace signals it may name directly (`x`)."""
    sink = DiagnosticSink()
    node = parse_expression(text, FORMULA_PATH, sink)
    formula = None
    if node is not None:
        names = _actor_and_node_names(node)
        scope = Scope(dict(params or {}), names, names, True, set(), dict(signals or {}), _step_names(node),
                      lights=names, variables=names)
        formula = ExprLowering(sink, scope).lower_formula(node, "a formula")
    if formula is None or sink.has_errors:
        raise FormulaError(text, sink.items)
    return formula


def _actor_and_node_names(node: ast.Node) -> set[str]:
    """Names in actor or node position: `lead` in `lead.speed`, `ego` and `lead` in
    `ttc(ego, lead)`. The signal functions themselves are still checked."""
    found: set[str] = set()
    stack = [node]
    while stack:
        n = stack.pop()
        if isinstance(n, ast.Ref) and len(n.parts) == 2:
            found.add(n.parts[0])
        elif isinstance(n, ast.CallExpr) and n.fn not in ARITH_FUNCS:
            found.update(a.parts[0] for a in n.args if isinstance(a, ast.Ref) and len(a.parts) == 1)
        for f in dataclasses.fields(n):
            value = getattr(n, f.name)
            stack.extend(v for v in (value if isinstance(value, tuple) else (value,)) if isinstance(v, ast.Node))
    return found


def _step_names(node: ast.Node) -> set[str]:
    """Named steps in step position: `lead.brake_hard` in `ended(lead.brake_hard)`."""
    found: set[str] = set()
    stack = [node]
    while stack:
        n = stack.pop()
        cls = SIGNALS.get(n.fn) if isinstance(n, ast.CallExpr) else None
        if cls is not None and "step" in cls.args:
            found.update(a.dotted for a in n.args if isinstance(a, ast.Ref) and len(a.parts) == 2)
        for f in dataclasses.fields(n):
            value = getattr(n, f.name)
            stack.extend(v for v in (value if isinstance(value, tuple) else (value,)) if isinstance(v, ast.Node))
    return found
