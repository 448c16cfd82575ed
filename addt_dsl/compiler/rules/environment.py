"""The `environment { }` block: weather and light models, checked against their registry,
and their changes during the run (`at 10 s fog visibility 20 m`) as steps."""

from __future__ import annotations

from dataclasses import dataclass

from addt_dsl import plan as P
from addt_dsl.compiler import ast
from addt_dsl.compiler.context import Context, check_settings, lower_starts, suggest, validate_settings
from addt_dsl.registry import ENVIRONMENTS


@dataclass(frozen=True)
class Environment:
    environment: list[P.ClausePlan]
    environment_steps: list[P.TriggerPlan]


def rule_environment(ctx: Context) -> Environment:
    out: list[P.ClausePlan] = []
    steps: list[P.TriggerPlan] = []
    seen: dict[str, ast.EnvItem] = {}
    for block in ctx.defs(ast.Block):
        if block.kind != "environment":
            continue
        for item in block.items:
            if isinstance(item, ast.EnvStep):
                step = _step(ctx, item)
                if step is not None:
                    steps.append(step)
                continue
            if ENVIRONMENTS.get(item.name) is not None and item.name in seen:
                ctx.sink.error("E0102", f"'{item.name}' is given twice", item.name_span,
                               f"first given at {seen[item.name].name_span}",
                               "a change during the run is a step: `at 10 s fog visibility 20 m`")
                continue
            clause = _model(ctx, item)
            seen.setdefault(item.name, item)
            if clause is not None:
                out.append(clause)
    return Environment(out, steps)


def _model(ctx: Context, item: ast.EnvItem) -> P.ClausePlan | None:
    cls = ENVIRONMENTS.get(item.name)
    if cls is None:
        ctx.sink.error("E0106", f"unknown environment model '{item.name}'", item.name_span,
                       *suggest(item.name, ENVIRONMENTS.names()),
                       f"models: {', '.join(ENVIRONMENTS.names())}")
        return None
    vals = check_settings(ctx, item.settings, cls.params, f"environment '{item.name}'", item.span)
    if not validate_settings(ctx, cls, vals, item.settings, item.span):
        return None
    return P.ClausePlan(keyword="environment", name=item.name, settings=vals)


def _step(ctx: Context, node: ast.EnvStep) -> P.TriggerPlan | None:
    """A change of one model from its start on: the model's settings replace the ones it had
    (a model not declared before starts acting then)."""
    starts = lower_starts(ctx, node.starts)
    ok = starts.ok
    if starts.when is not None and starts.when.repeat is not None:
        ctx.sink.error("E0204", "an environment change fires once: `repeat` is for an actor's steps",
                       starts.nodes["when"].repeat.span)
        ok = False
    clause = _model(ctx, node.item)
    if not ok or clause is None:
        return None
    return P.TriggerPlan(clause=clause, **starts.fields)
