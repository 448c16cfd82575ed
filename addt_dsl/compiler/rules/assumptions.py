"""Constraints between parameters (`assume` / `keep`): a sample that breaks one is rejected."""

from __future__ import annotations

from dataclasses import dataclass

from addt_dsl import expr as E
from addt_dsl import plan as P
from addt_dsl.compiler import ast
from addt_dsl.compiler.context import Context, const_value, text_of
from addt_dsl.compiler.exprs import narrowed_ranges
from addt_dsl.diagnostics import Span


@dataclass(frozen=True)
class Assumptions:
    assumptions: list[P.AssumptionPlan]
    # The parameters' ranges narrowed by the constraints, for every later check of a
    # value over parameters ("can be outside ...": the runs' values, not the declared ranges).
    param_ranges: dict[str, tuple[float, float]]


def rule_assumptions(ctx: Context) -> Assumptions:
    out = Assumptions([], {})
    names: dict[str, Span] = {}
    for d in ctx.defs(ast.AssumeDecl):
        if d.label is not None:
            if d.label in names:
                ctx.sink.error("E0102", f"constraint '{d.label}' is defined twice", d.span,
                               f"first defined at {names[d.label]}")
                continue
            names[d.label] = d.span
        low = ctx.lowering(signals=False)
        formula = low.lower_formula(d.expr, "a constraint")
        if formula is None:
            continue
        if not E.params_used(formula):
            holds = const_value(formula)
            if holds is not None and not holds:
                ctx.sink.error("E0501", "this constraint never holds", d.expr.span,
                               "it uses no parameter, and it is false")
            else:
                ctx.sink.warning("W0002", "this constraint always holds: it uses no parameter", d.expr.span)
            continue
        out.assumptions.append(P.AssumptionPlan(name=d.label or "", text=text_of(ctx, d.expr.span), expr=formula))
    out.param_ranges.update(narrowed_ranges(ctx.param_ranges, [a.expr for a in out.assumptions]))
    return out
