"""`end when C [delayed D]`: a condition that ends the run (OpenSCENARIO's storyboard stop
trigger), checked like a step's start; `duration` stays the longest the run may take."""

from __future__ import annotations

from dataclasses import dataclass

from addt_dsl import plan as P
from addt_dsl import units
from addt_dsl.compiler import ast
from addt_dsl.compiler.context import Context, check_time, lower_when, when_fields


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
    starts: dict[str, ast.StepStart] = {}
    ok = True
    for st in node.starts:
        if st.kind in starts:
            ctx.sink.error("E0102", f"`{st.kind}` given twice in `end`", st.span)
            ok = False
        starts[st.kind] = st
    fields: dict = {}
    low = ctx.lowering()
    for kind, key in (("at", "at_s"), ("after", "after_s")):
        if kind in starts:
            value = low.lower_value(starts[kind].value, units.TIME, f"the time of `{kind}`")
            if value is None or not check_time(ctx, value, starts[kind].value.span, f"`{kind}`"):
                ok = False
            fields[key] = value
    if "when" in starts:
        when = lower_when(ctx, starts["when"])
        if when is None:
            ok = False
        elif when.repeat is not None:
            ctx.sink.error("E0204", "a run ends once: `repeat` is for an actor's steps", starts["when"].repeat.span)
            ok = False
        else:
            fields.update(when_fields(when))
    return Ending(P.TriggerPlan(**fields) if ok else None)
