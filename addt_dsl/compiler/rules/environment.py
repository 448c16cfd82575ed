"""The `environment { }` block: weather and light models, checked against their registry."""

from __future__ import annotations

from dataclasses import dataclass

from addt_dsl import plan as P
from addt_dsl.compiler import ast
from addt_dsl.compiler.context import Context, check_settings, suggest
from addt_dsl.registry import ENVIRONMENTS


@dataclass(frozen=True)
class Environment:
    environment: list[P.ClausePlan]


def rule_environment(ctx: Context) -> Environment:
    out: list[P.ClausePlan] = []
    seen: dict[str, ast.EnvItem] = {}
    for block in ctx.defs(ast.Block):
        if block.kind != "environment":
            continue
        for item in block.items:
            cls = ENVIRONMENTS.get(item.name)
            if cls is None:
                ctx.sink.error("E0106", f"unknown environment model '{item.name}'", item.name_span,
                               *suggest(item.name, ENVIRONMENTS.names()),
                               f"models: {', '.join(ENVIRONMENTS.names())}")
                continue
            if item.name in seen:
                ctx.sink.error("E0102", f"'{item.name}' is given twice", item.name_span,
                               f"first given at {seen[item.name].name_span}")
                continue
            seen[item.name] = item
            vals = check_settings(ctx, item.settings, cls.params, f"environment '{item.name}'", item.span)
            out.append(P.ClausePlan(keyword="environment", name=item.name, settings=vals))
    return Environment(out)
