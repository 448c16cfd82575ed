"""`end when C [delayed D]`: a condition that ends the run (OpenSCENARIO's storyboard stop
trigger), checked like a step's start; `duration` stays the longest the run may take."""

from __future__ import annotations

from dataclasses import dataclass

from addt_dsl import plan as P
from addt_dsl.compiler import ast
from addt_dsl.compiler.context import Context, lower_starts


@dataclass(frozen=True)
class Ending:
    end: P.TriggerPlan | None


def rule_end(ctx: Context) -> Ending:
    ends = ctx.defs(ast.EndWhen)
    if not ends:
        return Ending(None)
    for extra in ends[1:]:
        ctx.sink.error("E0102", "a scenario has one `end`", extra.span, f"first given at {ends[0].span}",
                       "join the conditions with `or`: `end when C1 or C2`")
    node = ends[0]
    starts = lower_starts(ctx, node.starts)
    ok = starts.ok
    if starts.when is not None and starts.when.repeat is not None:
        ctx.sink.error("E0204", "a run ends once: `repeat` is for an actor's steps", starts.nodes["when"].repeat.span)
        ok = False
    return Ending(P.TriggerPlan(**starts.fields) if ok else None)
