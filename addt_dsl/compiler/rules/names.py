"""Declarations: roads, parameters and actors by name; duplicates are errors; a scenario
needs an ego and a road."""

from __future__ import annotations

from dataclasses import dataclass

from addt_dsl.compiler import ast
from addt_dsl.compiler.context import Context
from addt_dsl.diagnostics import Span


@dataclass(frozen=True)
class Declarations:
    roads_ast: dict[str, ast.RoadDecl]
    params_ast: dict[str, ast.ParamDecl]
    actors_ast: dict[str, ast.ActorDecl]
    step_names: dict[str, Span]  # `actor.label` of each named step


def rule_names(ctx: Context) -> Declarations:
    """Collect declarations; duplicates are errors."""
    out = Declarations({}, {}, {}, {})
    for kind, table in ((ast.RoadDecl, out.roads_ast), (ast.ParamDecl, out.params_ast),
                        (ast.ActorDecl, out.actors_ast)):
        for d in ctx.defs(kind):
            if d.name in table:
                ctx.sink.error("E0102", f"'{d.name}' is defined twice", d.span,
                               f"first defined at {table[d.name].span}")
                continue
            if kind is ast.ActorDecl and d.name in out.params_ast:
                ctx.sink.error("E0102", f"'{d.name}' is already a parameter", d.span,
                               f"the parameter is defined at {out.params_ast[d.name].span}")
                continue
            table[d.name] = d
    # Unique per actor: a step is always named with its actor (`started(lead.brake)`), so two
    # actors may each have a step `brake`.
    for actor in out.actors_ast.values():
        for node in _named(actor.steps):
            key = f"{actor.name}.{node.label}"
            if key in out.step_names:
                ctx.sink.error("E0102", f"step '{node.label}' of '{actor.name}' is named twice", node.label_span,
                               f"first named at {out.step_names[key]}")
                continue
            out.step_names[key] = node.label_span
    egos = [a for a in ctx.defs(ast.ActorDecl) if a.is_ego]
    if not egos:
        ctx.sink.error("E0103", f"scenario '{ctx.scenario.name}' has no ego vehicle", ctx.scenario.span,
                       "add e.g. `ego car on road1 lane -1 at 10 m speed 20 m/s`")
    if not out.roads_ast:
        ctx.sink.error("E0103", f"scenario '{ctx.scenario.name}' has no road", ctx.scenario.span,
                       "add e.g. `road main { line length 500 m }`")
    return out


def _named(items):
    """The named steps and groups of a script, depth first in source order."""
    for item in items:
        if isinstance(item, (ast.Step, ast.Group)) and item.label is not None:
            yield item
        if isinstance(item, ast.Step):
            yield from _named((item.action,))
        elif isinstance(item, ast.Group):
            yield from _named(item.items)
