"""The `variables { }` block: scenario variables with their first values, and the steps that
set them during the run (`at 3 s set phase 1`); conditions and oracles read them as
`var(NAME)`."""

from __future__ import annotations

from dataclasses import dataclass

from addt_dsl import plan as P
from addt_dsl import units
from addt_dsl.compiler import ast
from addt_dsl.compiler.context import Context, const_value, lower_starts, suggest


@dataclass(frozen=True)
class Variables:
    variables: list[P.VariablePlan]
    variable_steps: list[P.TriggerPlan]


def rule_variables(ctx: Context) -> Variables:
    out: list[P.VariablePlan] = []
    steps: list[P.TriggerPlan] = []
    seen: dict[str, ast.VarDef] = {}
    low = ctx.lowering()
    for block in ctx.blocks("variables"):
        for item in block.items:
            if isinstance(item, ast.VarStep):
                step = _step(ctx, item)
                if step is not None:
                    steps.append(step)
                continue
            if item.name in seen:
                ctx.sink.error("E0102", f"variable '{item.name}' is declared twice", item.name_span,
                               f"first declared at {seen[item.name].name_span}",
                               "a change during the run is a step: `at 3 s set NAME VALUE`")
                continue
            seen[item.name] = item
            value = low.lower_value(item.value, units.DIMENSIONLESS, "a variable's first value")
            number = const_value(value) if value is not None else None
            if value is not None and number is None:
                ctx.sink.error("E0204", "a variable's first value is a number", item.value.span)
            if number is not None:
                out.append(P.VariablePlan(name=item.name, value=number))
    return Variables(out, steps)


def _step(ctx: Context, node: ast.VarStep) -> P.TriggerPlan | None:
    """A step that sets a variable to a value (a number, or parameters) when it fires."""
    starts = lower_starts(ctx, node.starts)
    ok = starts.ok
    if starts.when is not None and starts.when.repeat is not None:
        ctx.sink.error("E0204", "a variable step fires once: `repeat` is for an actor's steps",
                       starts.nodes["when"].repeat.span)
        ok = False
    known = ctx.variable_names()
    if node.name not in known:
        ctx.sink.error("E0101", f"unknown variable '{node.name}'", node.name_span,
                       *suggest(node.name, sorted(known)),
                       f"variables: {', '.join(sorted(known))}" if known else "declare it: `phase = 0`")
        ok = False
    value = ctx.lowering().lower_value(node.value, units.DIMENSIONLESS, "the value a step sets")
    if not ok or value is None:
        return None
    return P.TriggerPlan(clause=P.ClausePlan(keyword="set", name=node.name, settings={"value": value}),
                         **starts.fields)
