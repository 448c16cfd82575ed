"""Faults: kind from the `FAULTS` registry, its target (each kind says which it takes),
settings, seed, and time window inside the scenario."""

from __future__ import annotations

import functools
import inspect
from dataclasses import dataclass

from addt_dsl import expr as E
from addt_dsl import plan as P
from addt_dsl import units
from addt_dsl.compiler import ast
from addt_dsl.compiler.context import (Context, check_range, check_settings, check_time, const_value, fmt, int_const,
                                       lower_when, suggest, when_fields)
from addt_dsl.compiler.rules.actors import DEFAULT_SENSOR, DEFAULT_STACK, is_scripted_ego
from addt_dsl.diagnostics import Span
from addt_dsl.registry import FAULTS, SENSORS, STACKS, ParamSpec


def _window_of(ctx: Context, timing: ast.Timing | None):
    low = ctx.lowering(signals=False)
    if timing is None:
        return P.num(0.0), None
    # `when C for W`: the times count from where the condition fires, as `at 0 s for W` would.
    start = P.num(0.0) if timing.kind == "when" else low.lower_value(timing.start, units.TIME, "a fault time")
    if start is None:
        return None, None
    if timing.kind in ("at", "when"):
        if timing.length is not None:
            length = low.lower_value(timing.length, units.TIME, "a fault duration")
            if length is None:
                return None, None
            if not check_range(ctx, length, 0.0, None, units.TIME, "the fault's duration", timing.length.span):
                return None, None
            if timing.kind == "when":  # counted from the opening: the length is the end
                return start, length
            return start, _simplify(E.Binary(op="+", left=start, right=length))
        return (start, None) if timing.kind == "when" else (start, start)
    if timing.kind == "from":
        return start, None
    end = low.lower_value(timing.end, units.TIME, "a fault time")
    return start, end


def _opening(ctx: Context, timing: ast.Timing) -> P.TriggerPlan | None:
    """`when [rising] C [delayed D]` of a fault: a step's start, lowered and checked as one
    (conditions on the state, named steps, edges, delay); it fires once."""
    start = ast.StepStart(timing.span, "when", timing.start, None, timing.edge, timing.delay)
    when = lower_when(ctx, start)
    return P.TriggerPlan(**when_fields(when)) if when is not None else None


def _simplify(expr):
    const = const_value(expr)
    return E.Num(value=const) if const is not None else expr


@dataclass(frozen=True)
class Faults:
    faults: list[P.FaultPlan]


def rule_faults(ctx: Context) -> Faults:
    out = Faults([])
    # Targets come from the ego's declaration, so a fault is checked even when the ego
    # itself had an error elsewhere.
    ego = ctx.actors_ast.get("ego")
    clauses = ego.clauses if ego else ()
    sensors = {c.name for c in clauses if c.keyword == "sensor"} or {DEFAULT_SENSOR.name}
    stack_name = next((c.name for c in clauses if c.keyword == "stack"), DEFAULT_STACK.name)
    stack_cls = STACKS.get(stack_name)
    # A remote stack (`stack external`) declares whose fault sites it has (`sites bev`):
    # its stack-internal faults are checked against that stack, or refused (`sites none`).
    sites_of = getattr(stack_cls, "sites_of", None)
    site_cls = sites_of(_stack_settings(ctx)) if sites_of is not None else stack_cls
    sites = _fault_sites(ctx, site_cls) if site_cls else set()
    # A scripted ego without a `stack` clause has neither stack nor sensors to fault.
    stackless = ego is not None and is_scripted_ego(ego) and not any(c.keyword == "stack" for c in clauses)
    for block in ctx.blocks("faults"):
        for f in block.items:
            if stackless:
                ctx.sink.error("E0107", f"'{f.kind}' targets the ego's stack or sensors, and the scripted ego "
                                        "has neither", f.target_span,
                               "its behaviours and steps drive it; add a `stack` to the ego to run one open loop "
                               "(its commands are recorded, not applied) and fault that")
                continue
            cls = FAULTS.get(f.kind)
            if cls is None:
                ctx.sink.error("E0106", f"unknown fault kind '{f.kind}'", f.kind_span,
                               *suggest(f.kind, FAULTS.names()), f"fault kinds: {', '.join(FAULTS.names())}")
                continue
            target = ".".join(f.target)
            if cls.target_kind != "sensor" and stack_cls is not None and site_cls is None:
                why, hint = stack_cls.no_sites_reason(_stack_settings(ctx))
                ctx.sink.error("E0109", f"'{f.kind}' needs fault sites of the remote stack, and {why}",
                               f.target_span, hint)
                continue
            # Each kind says which targets it takes (an image fault only a camera, a bit flip
            # a site or a whole node); sites come with the ego's stack settings (tensors).
            pool = cls.valid_targets({name: name for name in sensors}, site_cls)
            if cls.target_kind == "site" and site_cls is not None:
                pool = (pool - set(site_cls.fault_sites())) | sites
            if target not in pool:
                what = {"sensor": "sensors of the ego", "site": "fault sites of the stack",
                        "node": "nodes of the stack"}[cls.target_kind]
                ctx.sink.error("E0107", f"'{f.kind}' cannot target '{target}'", f.target_span,
                               *suggest(target, pool),
                               f"{what}: {', '.join(sorted(pool)) or '(none)'}")
                continue
            specs = (*cls.params, ParamSpec("seed", None, kind="int", low=0, high=2**32 - 1, doc="fault seed"))
            vals = check_settings(ctx, f.settings, specs, f"fault '{f.kind}'", f.span)
            seed = vals.pop("seed", None)
            if cls.target_kind == "sensor" and not _fits_sensor(ctx, cls, f, target, vals):
                continue
            opens = None
            if f.timing is not None and f.timing.kind == "when":
                if cls.target_kind != "sensor" and sites_of is not None:
                    ctx.sink.error("E0204", f"'{f.kind}' on a remote stack cannot wait for a condition",
                                   f.timing.span, "the remote stack applies its internal faults on its own "
                                                  "clock, without the scenario's state: give the fault a time "
                                                  "window (`at T for D`, `during [A, B]`)")
                    continue
                opens = _opening(ctx, f.timing)
                if opens is None:
                    continue
            start, end = _window_of(ctx, f.timing)
            if start is None or (f.timing is not None and f.timing.kind == "during" and end is None):
                continue
            if opens is not None:  # the length counts from the opening: at most the duration
                if end is not None and not check_time(ctx, end, f.timing.length.span, "the window's length"):
                    continue
            elif not _check_window(ctx, start, end, f.timing.span if f.timing else f.span):
                continue
            out.faults.append(P.FaultPlan(kind=f.kind, target=target, start_s=start, end_s=end, settings=vals,
                                          seed=int_const(seed) if seed is not None else None,
                                          source=f"{f.span.file}:{f.span.line}", opens=opens))
    return out


def _fits_sensor(ctx: Context, cls, f: ast.FaultDecl, target: str, vals: dict) -> bool:
    """A kind's settings that depend on its target sensor's settings (an image fault's
    `lens` against the rig's `cameras`); constant settings only, defaults filled in."""
    problems_of = getattr(cls, "setting_problems", None)
    ego = ctx.actors.get("ego")
    sensor = next((s for s in ego.sensors if s.name == target), None) if ego is not None else None
    spec = SENSORS.get(target)
    if problems_of is None or sensor is None or spec is None:
        return True
    constants = {k: const_value(v) if not isinstance(v, str) else v for k, v in vals.items()}
    settings = {p.name: p.default for p in cls.params} | {k: v for k, v in constants.items() if v is not None}
    sensor_settings = {p.name: p.default for p in spec.params}
    sensor_settings |= {k: v if isinstance(v, str) else const_value(v) for k, v in sensor.settings.items()
                        if isinstance(v, str) or const_value(v) is not None}
    problems = problems_of(settings, sensor.name, sensor_settings)
    for key, why in problems.items():
        st = next((s for s in f.settings if s.key == key), None)
        ctx.sink.error("E0204", f"invalid value for setting '{key}' of fault '{f.kind}'",
                       st.value.span if st is not None else f.span, why)
    return not problems


def _fault_sites(ctx: Context, stack_cls) -> set[str]:
    """The stack's fault sites for the ego's stack settings (a stack whose sites depend on
    its settings, e.g. tensor sites with `perception learned`, takes them as an argument)."""
    if not _takes_settings(stack_cls):
        return set(stack_cls.fault_sites())
    return set(stack_cls.fault_sites(_stack_settings(ctx)))


def _stack_settings(ctx: Context) -> dict:
    """The ego's stack settings that are constants (words and numbers, SI)."""
    ego = ctx.actors.get("ego")
    lowered = ego.stack.settings if ego is not None and ego.stack is not None else {}
    settings = {k: v if isinstance(v, str) else const_value(v) for k, v in lowered.items()}
    return {k: v for k, v in settings.items() if v is not None}


@functools.lru_cache(maxsize=64)  # stack classes: a few per registry
def _takes_settings(stack_cls) -> bool:
    try:
        return len(inspect.signature(stack_cls.fault_sites).parameters) >= 1
    except (TypeError, ValueError):
        return False


def _check_window(ctx: Context, start, end, span: Span) -> bool:
    if not check_time(ctx, start, span, "the fault's start"):
        return False
    if end is not None and end is not start and not check_time(ctx, end, span, "the fault's end"):
        return False
    lo, hi = const_value(start), const_value(end) if end is not None else None
    if lo is not None and hi is not None and hi < lo:
        ctx.sink.error("E0303", "the window ends before it starts", span,
                       f"[{fmt(lo, units.TIME)}, {fmt(hi, units.TIME)}]")
        return False
    return True
