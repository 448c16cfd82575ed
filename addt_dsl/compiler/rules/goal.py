"""A goal on the ego adds the oracle `reach_goal` unless the expect block states one."""

from __future__ import annotations

from addt_dsl import plan as P
from addt_dsl.compiler.context import Context
from addt_dsl.compiler.rules.oracles import Oracles, reach_goal_formula


def rule_goal_oracle(ctx: Context) -> Oracles | None:
    """`goal 950 m` on the ego adds the oracle `eventually s(ego) >= goal` (last), unless
    an oracle is named `reach_goal` or the expect block states `reach goal` itself."""
    ego = ctx.actors.get("ego")
    if ego is None or ego.goal_s is None:
        return None
    if any(o.name == "reach_goal" for o in ctx.oracles):
        return None
    if any(o.builtin is not None and o.builtin.kind == "reach_goal" for b in ctx.blocks("expect") for o in b.items):
        return None
    implied = P.OraclePlan(name="reach_goal", severity="hard", formula=reach_goal_formula(ego.goal_s),
                           text="ego reaches its goal")
    return Oracles([*ctx.oracles, implied])
