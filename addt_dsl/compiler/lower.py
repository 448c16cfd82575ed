"""Assemble the `ScenarioPlan` from a checked context (all values already in SI)."""

from __future__ import annotations

from addt_dsl.compiler import ast
from addt_dsl.compiler.context import Context, text_of
from addt_dsl.plan import ScenarioPlan
from addt_dsl.sweep import probe_feasibility

FEASIBILITY_BUDGET = 2000  # candidate assignments tried at compile time


def build_plan(ctx: Context) -> ScenarioPlan:
    ego = ctx.actors["ego"]
    agents = [a for name, a in ctx.actors.items() if name != "ego"]
    return ScenarioPlan(
        name=ctx.scenario.name,
        description=ctx.header.get("description") or "",
        source_file=ctx.source_file,
        duration_s=float(ctx.header["duration"]),
        step_s=float(ctx.header.get("step") or 0.01),
        seed=int(ctx.header.get("seed") or 0),
        run_seed=None if ctx.header.get("run_seed") is None else int(ctx.header["run_seed"]),
        roads=ctx.roads,
        params=ctx.params,
        assumptions=ctx.assumptions,
        ego=ego,
        agents=agents,
        faults=ctx.faults,
        environment=ctx.environment,
        environment_steps=ctx.environment_steps,
        variables=ctx.variables,
        variable_steps=ctx.variable_steps,
        oracles=ctx.oracles,
        sweep=ctx.sweep,
        signals=ctx.signals,
        controllers=ctx.controllers,
        light_steps=ctx.light_steps,
        end=ctx.end,
    )


def check_feasible(plan: ScenarioPlan, ctx: Context) -> bool:
    """An unsatisfiable set of constraints is a compile error (E0501), never a silent
    loop: probe the sweep's candidates and report which constraints rejected them."""
    rejected = probe_feasibility(plan, FEASIBILITY_BUDGET)
    if rejected is None:
        return True
    worst = rejected.most_common(1)[0][0] if rejected else ""
    decl = next((d for d in ctx.defs(ast.AssumeDecl)
                 if worst in (d.label, text_of(ctx, d.expr.span))), None) or next(
        (d for d in ctx.defs(ast.AssumeDecl)), None)
    span = decl.span if decl is not None else ctx.scenario.span
    tried = FEASIBILITY_BUDGET
    ctx.sink.error("E0501", "no candidate run satisfies the constraints", span,
                   *[f"`{text}` rejected {n} candidate(s)" for text, n in rejected.most_common()],
                   f"tried up to {tried} candidates from the sweep; widen the parameter ranges or relax "
                   "the constraints")
    return False
