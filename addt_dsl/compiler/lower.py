"""Assemble the `ScenarioPlan` from a checked context (all values already in SI)."""

from __future__ import annotations

from addt_dsl.compiler.check import Context
from addt_dsl.plan import ScenarioPlan


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
        oracles=ctx.oracles,
        sweep=ctx.sweep,
    )
