"""Traffic lights (`lights { }`): signals on inline roads, controllers with their phase
programs, and state changes as steps (`at 5 s light west state red`).

Signal and controller ids are checked against the map (E0405, with the ids it has);
programs are times; steps take `at`/`after`/`when` like an agent's (no groups).
"""

from __future__ import annotations

from dataclasses import dataclass

from addt_dsl import expr as E
from addt_dsl import plan as P
from addt_dsl import units
from addt_dsl.compiler import ast
from addt_dsl.compiler.context import (Context, check_settings, const_value, int_const, lower_starts,
                                       suggest)
from addt_dsl.registry import ParamSpec

STATE_CHOICES = (*P.LIGHT_STATES, P.LIGHT_PROGRAM)

SIGNAL_SPECS = (
    ParamSpec("road", None, kind="name", doc="the inline road it stands on (default: the first road)"),
    ParamSpec("at", units.LENGTH, required=True, low=0.0, doc="its stop line: station along the road"),
    ParamSpec("lane", None, kind="int", doc="the lane it governs (default: every lane driven along +s)"),
)
CONTROLLER_SPECS = (
    ParamSpec("road", None, kind="name", doc="the road (map) its signals are on (default: the first road)"),
    ParamSpec("signals", None, kind="list", doc="ids of the signals that switch together"),
    ParamSpec("id", None, kind="list", doc="an OpenDRIVE <controller> of the map, by id"),
    ParamSpec("green", units.TIME, default=20.0, low=0.0, doc="green time of the cycle"),
    ParamSpec("yellow", units.TIME, default=3.0, low=0.0, doc="yellow time of the cycle"),
    ParamSpec("red", units.TIME, default=20.0, low=0.0, doc="red time of the cycle"),
    ParamSpec("offset", units.TIME, default=0.0, low=0.0, doc="when the first green starts"),
)
LIGHT_CLAUSE_SPECS = (
    ParamSpec("state", None, kind="word", required=True, choices=STATE_CHOICES,
              doc="the new state, or `program` to resume the phase program"),
)


@dataclass(frozen=True)
class Lights:
    signals: list[P.SignalPlan]
    controllers: list[P.ControllerPlan]
    light_steps: list[P.TriggerPlan]


def controller_names(scenario: ast.Scenario) -> set[str]:
    """Names of the scenario's controllers (formulas refer to them: `light(west)`)."""
    return {d.name for b in scenario.definitions if isinstance(b, ast.Block) and b.kind == "lights"
            for d in b.items if isinstance(d, ast.LightDef) and d.kind == "controller"}


def rule_lights(ctx: Context) -> Lights | None:
    items = [i for b in ctx.blocks("lights") for i in b.items]
    if not items:
        return None
    out = Lights([], [], [])
    inline: dict[str, P.SignalPlan] = {}
    defs = [i for i in items if isinstance(i, ast.LightDef)]
    # A bare `light NAME state S` line (no start condition) reads as a definition: it is a
    # state change at time 0.
    items = [ast.Clause(i.span, "light", i.name, i.name_span, i.settings)
             if isinstance(i, ast.LightDef) and i.kind == "light" else i for i in items]
    defs = [i for i in items if isinstance(i, ast.LightDef)]
    for d in defs:
        if d.kind not in ("signal", "controller"):
            ctx.sink.error("E0106", f"unknown lights item '{d.kind}'", d.kind_span,
                           *suggest(d.kind, ("signal", "controller")), "items: signal, controller, light steps")
    seen: dict[str, ast.LightDef] = {}
    for d in defs:
        if d.kind in ("signal", "controller"):
            if d.name in seen:
                ctx.sink.error("E0102", f"'{d.name}' is defined twice", d.name_span,
                               f"first defined at {seen[d.name].span}")
                continue
            seen[d.name] = d
        if d.kind == "signal":
            sig = _signal(ctx, d)
            if sig is not None:
                out.signals.append(sig)
                inline[sig.name] = sig
    for d in defs:
        if d.kind == "controller" and seen.get(d.name) is d:
            c = _controller(ctx, d, inline)
            if c is not None:
                out.controllers.append(c)
    names = {c.name for c in out.controllers}
    for item in items:
        if not isinstance(item, ast.LightDef):
            step = _step(ctx, item, names)
            if step is not None:
                out.light_steps.append(step)
    return out


def _default_road(ctx: Context) -> str | None:
    return next(iter(ctx.roads_ast), None)


def _road_setting(ctx: Context, d: ast.LightDef, vals: dict) -> str | None:
    road = vals.get("road") or _default_road(ctx)
    if road is not None and road not in ctx.roads_ast:
        span = next(st.value.span for st in d.settings if st.key == "road")
        ctx.sink.error("E0101", f"unknown road '{road}'", span, *suggest(road, ctx.roads_ast),
                       f"roads: {', '.join(sorted(ctx.roads_ast))}")
        return None
    return road


def _signal(ctx: Context, d: ast.LightDef) -> P.SignalPlan | None:
    vals = check_settings(ctx, d.settings, SIGNAL_SPECS, f"signal '{d.name}'", d.span)
    road = _road_setting(ctx, d, vals)
    if road is None or "at" not in vals:
        return None
    if ctx.roads_ast[road].import_path is not None:
        ctx.sink.error("E0405", f"signals of the imported road '{road}' come from its map", d.span,
                       "name the map's signal ids in a controller: `controller c signals [1, 2]`")
        return None
    s = const_value(vals["at"])
    if s is None:
        ctx.sink.error("E0204", "a signal's position must be a constant", d.span)
        return None
    info = ctx.road_info.get(road)
    lanes = []
    if "lane" in vals:
        lane = int_const(vals["lane"])
        span = next(st.value.span for st in d.settings if st.key == "lane")
        if lane is None:
            ctx.sink.error("E0204", "a signal's lane must be a constant", span)
            return None
        if info is not None and lane not in info.lane_ids:
            ctx.sink.error("E0301", f"road '{road}' has no lane {lane}", span,
                           f"lanes of '{road}': {', '.join(str(i) for i in info.lane_ids)}")
            return None
        lanes = [lane]
    if info is not None and not 0.0 <= s <= info.length_m:
        span = next(st.value.span for st in d.settings if st.key == "at")
        ctx.sink.error("E0301", f"the signal stands off road '{road}' ({info.length_m:g} m long)", span)
        return None
    return P.SignalPlan(name=d.name, road=road, s_m=s, lanes=lanes)


def _ids(ctx: Context, d: ast.LightDef, key: str) -> list[tuple[str, object]] | None:
    """The ids listed by setting `key` (`[1, 2]`, `[s1]`, `["a"]` or one id), with spans."""
    st = next((st for st in d.settings if st.key == key), None)
    if st is None:
        return []
    items = st.value.items if isinstance(st.value, ast.ListExpr) else (st.value,)
    out = []
    for item in items:
        if isinstance(item, ast.Number) and item.unit is None and float(item.value).is_integer():
            out.append((str(int(item.value)), item.span))
        elif isinstance(item, ast.UnaryExpr) and item.op == "neg" and isinstance(item.arg, ast.Number):
            out.append((str(-int(item.arg.value)), item.span))
        elif isinstance(item, ast.Ref) and len(item.parts) == 1:
            out.append((item.parts[0], item.span))
        elif isinstance(item, ast.Str):
            out.append((item.value, item.span))
        else:
            ctx.sink.error("E0204", f"'{key}' lists signal ids: numbers, names or strings", item.span)
            return None
    return out


def _controller(ctx: Context, d: ast.LightDef, inline: dict[str, P.SignalPlan]) -> P.ControllerPlan | None:
    # `signals` and `id` list ids (checked here, not as numbers).
    plain = tuple(st for st in d.settings if st.key not in ("signals", "id"))
    specs = tuple(s for s in CONTROLLER_SPECS if s.name not in ("signals", "id"))
    vals = check_settings(ctx, plain, specs, f"controller '{d.name}'", d.span)
    signals, ids = _ids(ctx, d, "signals"), _ids(ctx, d, "id")
    if signals is None or ids is None:
        return None
    if not signals and not ids:
        ctx.sink.error("E0105", f"controller '{d.name}' needs `signals [...]` or a map controller `id`", d.span,
                       "e.g. `controller west signals [1, 2] green 20 s yellow 3 s red 25 s`")
        return None
    roads = {sig.road for sid, _ in signals if (sig := inline.get(sid)) is not None}
    road = vals.get("road") or (next(iter(roads)) if len(roads) == 1 else None)
    if road is None:
        road = _road_setting(ctx, d, vals)
    elif road not in ctx.roads_ast:
        road = _road_setting(ctx, d, vals)
    if road is None:
        return None
    decl = ctx.roads_ast[road]
    ok = True
    ids_out: list[str] = []
    if decl.import_path is None:
        known = sorted(n for n, sig in inline.items() if sig.road == road)
        for sid, span in ids:
            ctx.sink.error("E0405", f"road '{road}' is inline: it has no map controller '{sid}'", span,
                           "declare its signals with `signal NAME road R at S` and list them in `signals [...]`")
            ok = False
        for sid, span in signals:
            if sid not in known:
                ctx.sink.error("E0405", f"no signal '{sid}' on road '{road}'", span, *suggest(sid, known),
                               f"signals declared on '{road}': {', '.join(known) or '(none)'}")
                ok = False
            ids_out.append(sid)
    else:
        network = (ctx.road_info.get(road).network if ctx.road_info.get(road) is not None else None)
        if network is None:
            return None  # the import failed and was reported
        dynamic = network.signal_ids(dynamic_only=True)
        for cid, span in ids:
            ctl = network.controllers.get(cid)
            if ctl is None:
                listed = ", ".join(f"{c.id} ({', '.join(c.signal_ids)})" for c in network.controllers.values())
                ctx.sink.error("E0405", f"no controller '{cid}' in {decl.import_path}", span,
                               *suggest(cid, network.controllers),
                               f"controllers on the map: {listed}" if listed else
                               "the map has no <controller>: list its signals instead, "
                               f"`signals [{', '.join(dynamic)}]`")
                ok = False
                continue
            ids_out.extend(ctl.signal_ids)
        for sid, span in signals:
            if network.signal(sid) is None:
                ctx.sink.error("E0405", f"no signal '{sid}' in {decl.import_path}", span,
                               *suggest(sid, network.signal_ids()),
                               f"traffic lights on the map (dynamic signals): {', '.join(dynamic) or '(none)'}")
                ok = False
            ids_out.append(sid)
    if not ok:
        return None
    times = {k: vals.get(k, E.Num(value=float(spec.default))) for k, spec in
             ((s.name, s) for s in specs if s.dim is units.TIME)}
    return P.ControllerPlan(name=d.name, road=road, signals=list(dict.fromkeys(ids_out)),
                            green_s=times["green"], yellow_s=times["yellow"], red_s=times["red"],
                            offset_s=times["offset"])


def check_light_clause(ctx: Context, c: ast.Clause, controllers: set[str]) -> P.ClausePlan | None:
    """`light CONTROLLER state S`: a state change of a declared controller."""
    vals = check_settings(ctx, c.settings + c.block, LIGHT_CLAUSE_SPECS, f"light '{c.name}'", c.span)
    if c.name not in controllers:
        ctx.sink.error("E0405", f"no controller '{c.name}'", c.name_span, *suggest(c.name, controllers),
                       f"controllers: {', '.join(sorted(controllers)) or '(none; declare one in `lights { }`)'}")
        return None
    if "state" not in vals:
        return None
    return P.ClausePlan(keyword="light", name=c.name, settings=vals)


def _step(ctx: Context, node, controllers: set[str]) -> P.TriggerPlan | None:
    """A state change: a bare `light` clause (at time 0) or a step with `at`/`after`/`when`."""
    if isinstance(node, ast.Clause):
        if node.keyword != "light":
            ctx.sink.error("E0204", f"`{node.keyword}` clauses belong in an actor's block", node.span,
                           "a lights block holds signals, controllers and `light` steps")
            return None
        clause = check_light_clause(ctx, node, controllers)
        return P.TriggerPlan(clause=clause) if clause is not None else None
    if isinstance(node, ast.Group) or isinstance(getattr(node, "action", None), ast.Group):
        ctx.sink.error("E0204", "a lights block takes steps, not `sequence`/`parallel` groups", node.span,
                       "write one step per change: `at 5 s light west state red`")
        return None
    starts = lower_starts(ctx, node.starts)
    ok = starts.ok
    if starts.when is not None and starts.when.repeat is not None:
        ctx.sink.error("E0204", "a light step fires once: `repeat` is for an actor's steps",
                       starts.nodes["when"].repeat.span)
        ok = False
    if node.action.keyword != "light":
        ctx.sink.error("E0204", f"`{node.action.keyword}` clauses belong in an actor's block", node.action.span,
                       "a lights block's steps change lights: `at 5 s light west state red`")
        return None
    clause = check_light_clause(ctx, node.action, controllers)
    if not ok or clause is None:
        return None
    return P.TriggerPlan(clause=clause, **starts.fields)
