"""Header settings (`duration`, `step`, `seed`, ...): constants only."""

from __future__ import annotations

from dataclasses import dataclass

from addt_dsl import expr as E
from addt_dsl import units
from addt_dsl.compiler.context import Context, check_settings, const_value
from addt_dsl.registry import ParamSpec

HEADER = {
    "description": ParamSpec("description", None, kind="string", doc="free text"),
    "duration": ParamSpec("duration", units.TIME, required=True, low=0.1, high=3600.0, doc="simulated time"),
    "step": ParamSpec("step", units.TIME, default=0.01, low=0.001, high=0.1, doc="physics step"),
    "seed": ParamSpec("seed", None, kind="int", default=0, low=0, high=2**31 - 1, doc="base seed"),
    "run_seed": ParamSpec("run_seed", None, kind="int", low=0, high=2**32 - 1,
                          doc="pins every run's seed (replay files)"),
}


@dataclass(frozen=True)
class Header:
    header: dict  # keyword: constant (SI) or string


def rule_header(ctx: Context) -> Header:
    header = {}
    values = check_settings(ctx, ctx.scenario.settings, HEADER.values(), "the scenario", ctx.scenario.span)
    for key, spec in HEADER.items():
        v = values.get(key, spec.default)
        if isinstance(v, (E.Num, E.Binary, E.Unary, E.Call, E.Param)):
            const = const_value(v)
            if const is None:
                st = next(s for s in ctx.scenario.settings if s.key == key)
                ctx.sink.error("E0204", f"'{key}' must be a constant, not a parameter", st.value.span)
                continue
            v = const
        header[key] = v
    dur, step = header.get("duration"), header.get("step")
    if isinstance(dur, float) and isinstance(step, float) and step > dur:
        ctx.sink.error("E0301", "the physics step is longer than the scenario", ctx.scenario.span)
    return Header(header)
