"""Actors: vehicle kind, body, placement (absolute or relative, in dependency order), the
ego's stack and sensors, behaviours and scripts (steps and groups) of agents and of a
scripted ego (one with a behaviour or a step: no stack unless it names one, which then
runs open loop)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from addt_dsl import expr as E
from addt_dsl import plan as P
from addt_dsl import units
from addt_dsl.compiler import ast
from addt_dsl.compiler.context import (Context, check_range, check_settings, const_value, fmt, int_const,
                                       lower_starts, suggest, validate_settings)
from addt_dsl.compiler.exprs import value_range
from addt_dsl.compiler.xodr_check import check_route, route_length
from addt_dsl.diagnostics import Span
from addt_dsl.registry import BEHAVIORS, SENSORS, STACKS, ParamSpec
from addt_dsl.vehicles import DEFAULT_MASS_KG, DEFAULT_MU, DEFAULT_WHEELBASE_M, STATIC_KINDS, VEHICLES


ACTOR_SETTINGS = (
    ParamSpec("on", None, kind="name", doc="road the actor starts on"),
    ParamSpec("lane", None, kind="int", low=-20, high=20, doc="lane id (OpenDRIVE: < 0 right of the reference line)"),
    ParamSpec("at", units.LENGTH, low=0.0, doc="station along the road"),
    ParamSpec("speed", units.SPEED, default=0.0, low=0.0, high=100.0, doc="initial speed"),
    ParamSpec("goal", units.LENGTH, low=0.0, doc="station the ego must reach (ego only)"),
    ParamSpec("length", units.LENGTH, low=0.1, high=30.0, doc="body length"),
    ParamSpec("width", units.LENGTH, low=0.1, high=5.0, doc="body width"),
    ParamSpec("height", units.LENGTH, low=0.05, high=10.0,
              doc="body height (what a lidar ray or a camera meets; default: the kind's)"),
    ParamSpec("mass", units.MASS, default=DEFAULT_MASS_KG, low=50.0, high=60000.0, doc="mass"),
    ParamSpec("wheelbase", units.LENGTH, default=DEFAULT_WHEELBASE_M, low=0.5, high=10.0, doc="wheelbase"),
    ParamSpec("mu", units.DIMENSIONLESS, default=DEFAULT_MU, low=0.05, high=1.5,
              doc="tyre-road friction coefficient (0.8 dry asphalt, 0.5 wet, 0.1 ice)"),
    ParamSpec("offset", units.LENGTH, default=0.0, low=-20.0, high=20.0,
              doc="start offset from the lane centre, left positive (e.g. a pedestrian on the kerb)"),
    ParamSpec("yaw", units.ANGLE, default=0.0, low=-3.1416, high=3.1416,
              doc="body yaw relative to the lane's driving direction, left positive (an angled or parked car)"),
    ParamSpec("direction", None, kind="word", default="lane", choices=("lane", "reverse"),
              doc="`lane`: drive the lane's way (OpenDRIVE); `reverse`: against it (a wrong-way driver, or a car "
                  "overtaking in the oncoming lane)"),
    ParamSpec("at_red", None, kind="word", default="stop", choices=("stop", "run"),
              doc="agents: `stop` at red (and yellow) traffic lights on their lane, or `run` them"),
    ParamSpec("at_road_end", None, kind="word", default="go", choices=("go", "stop"),
              doc="agents and a scripted ego: `go` on straight past the end of their road or route, or `stop` "
                  "there (as esmini's entities do)"),
)

# The ego's lidar when it declares no sensor: five channels from level to 4 deg down (0, -1,
# ... -4 deg at 1 m), so that it sees what a test engineer puts on the road, not only what
# reaches above its mount (a one-channel level lidar at 1 m is blind to anything 1 m tall
# or lower). Measured (ground truth, 1 deg rays, two returns): a car seen from 78 m as
# before, a 1 m or 0.5 m box from 55 m, a 0.3 m one from 26 m.
DEFAULT_SENSOR = P.ClausePlan(keyword="sensor", name="lidar", settings={
    "channels": P.Num(kind="num", value=5.0), "vfov": P.Num(kind="num", value=math.radians(4.0)),
    "pitch": P.Num(kind="num", value=math.radians(2.0))})
DEFAULT_STACK = P.ClausePlan(keyword="stack", name="bev", settings={})


@dataclass(frozen=True)
class Actors:
    actors: dict[str, P.ActorPlan]  # by name, in placement order


def rule_actors(ctx: Context) -> Actors:
    out = Actors({})
    for name in _placement_order(ctx):
        plan = _check_actor(ctx, ctx.actors_ast[name], out.actors)
        if plan is not None:
            out.actors[name] = plan
    _check_lidar_reach(ctx, out.actors)
    return out


def lidar_reach(mount_z: float, elevations: list[float], range_m: float, height_m: float) -> float:
    """The farthest distance [m] at which a ray of a lidar mounted `mount_z` [m] over level
    ground, at these elevations [rad] (up positive), meets a box `height_m` tall standing on
    the ground: 0 when every ray passes over it (or reaches the ground before it)."""
    best = 0.0
    for el in elevations:
        slope = math.tan(el)
        if slope >= 0:  # level or rising: under the box's top from the start, or never
            if mount_z < height_m:
                best = max(best, range_m if slope == 0 else min(range_m, (height_m - mount_z) / slope))
            continue
        ground = mount_z / -slope  # where the ray meets the ground
        under_top = max(0.0, (mount_z - height_m) / -slope)  # from here on it is below the box's top
        if under_top < min(ground, range_m):
            best = max(best, min(ground, range_m))
    return best


def _check_lidar_reach(ctx: Context, actors: dict[str, P.ActorPlan]) -> None:
    """An agent no ray of the ego's lidars meets (shorter than the lowest ray's height over
    its whole range) is never perceived by a stack that sees through them: a warning."""
    ego = actors.get("ego")
    if ego is None or ego.stack is None:
        return
    if ego.stack.settings.get("perception", "ground_truth") not in ("ground_truth", "learned"):
        return  # cameras see it whatever the lidar does
    rays = []  # (mount height [m], elevations [rad], range [m]) per lidar
    for sensor in ego.sensors:
        cls = SENSORS.get(sensor.name)
        if sensor.name != "lidar" or cls is None:
            continue
        values = {p.name: p.default for p in cls.params if isinstance(p.default, (int, float))}
        for key in ("z", "pitch", "channels", "vfov", "range"):
            if key in sensor.settings:
                if not isinstance(sensor.settings[key], P.Num):
                    return  # set by a parameter: the rays move with it
                values[key] = sensor.settings[key].value
        ch, vfov = int(values["channels"]), float(values["vfov"])
        elevations = ([(k / (ch - 1) - 0.5) * vfov - values["pitch"] for k in range(ch)] if ch > 1
                      else [-values["pitch"]])
        rays.append((float(values["z"]), elevations, float(values["range"])))
    if not rays:
        return
    for name, actor in actors.items():
        if name == "ego" or actor.height_m is None:
            continue
        if max(lidar_reach(z, els, rng, actor.height_m) for z, els, rng in rays) > 0.0:
            continue
        d = ctx.actors_ast[name]
        span = next((st.value.span for st in d.settings + d.block_settings if st.key == "height"), d.vehicle_span)
        lowest = min(z + rng * math.tan(min(els)) if min(els) < 0 else z for z, els, rng in rays)
        ctx.sink.warning("W0004", f"'{name}' ({fmt(actor.height_m, units.LENGTH)} tall) is under every ray of the "
                                  f"ego's lidar (none lower than {fmt(max(lowest, 0.0), units.LENGTH)} within its "
                                  "range on level ground): the stack never perceives it", span,
                         "give it its real `height`, or mount the lidar lower (`sensor lidar z ...`) or tilt "
                         "rays down (`channels`, `vfov`, `pitch`)")


def _placement_order(ctx: Context) -> list[str]:
    """Actors in an order where those placed relative to others come after them."""
    deps: dict[str, list[ast.Placement]] = {}
    for name, d in ctx.actors_ast.items():
        deps[name] = []
        for p in d.placements:
            if p.actor == name:
                ctx.sink.error("E0108", f"'{name}' is placed relative to itself", p.actor_span)
            elif p.actor not in ctx.actors_ast:
                ctx.sink.error("E0101", f"unknown actor '{p.actor}'", p.actor_span,
                               *suggest(p.actor, ctx.actors_ast),
                               f"actors: {', '.join(sorted(ctx.actors_ast))}")
            else:
                deps[name].append(p)
    order, state = [], {}

    def visit(name: str, chain: list[str]) -> None:
        if state.get(name) == "done":
            return
        if state.get(name) == "visiting":
            start = chain.index(name)
            cycle = chain[start:] + [name]
            d = ctx.actors_ast[name]
            ctx.sink.error("E0108", "actors are placed relative to each other in a cycle", d.span,
                           "cycle: " + " → ".join(cycle))
            return
        state[name] = "visiting"
        for p in deps[name]:
            visit(p.actor, chain + [name])
        state[name] = "done"
        order.append(name)

    for name in ctx.actors_ast:
        visit(name, [])
    return order


def _check_actor(ctx: Context, d: ast.ActorDecl, placed: dict[str, P.ActorPlan]) -> P.ActorPlan | None:
    """The actor's plan (others it is placed relative to are in `placed`), or None."""
    if d.vehicle not in VEHICLES:
        ctx.sink.error("E0106", f"unknown vehicle kind '{d.vehicle}'", d.vehicle_span,
                       *suggest(d.vehicle, VEHICLES), f"kinds: {', '.join(VEHICLES)}")
        return None
    what = "the ego" if d.is_ego else f"agent '{d.name}'"
    vals = check_settings(ctx, d.settings + d.block_settings, ACTOR_SETTINGS, what, d.span)
    kind = VEHICLES[d.vehicle]
    body = {"length": kind.length_m, "width": kind.width_m, "height": kind.height_m, "mass": DEFAULT_MASS_KG,
            "wheelbase": DEFAULT_WHEELBASE_M}
    for key in body:
        if key in vals:
            value = const_value(vals[key])
            if value is None:
                span = next(st.value.span for st in d.settings + d.block_settings if st.key == key)
                ctx.sink.error("E0204", f"'{key}' must be a constant, not a parameter", span,
                               "the body and dynamics of an actor are fixed for a scenario")
                return None
            body[key] = value
    length, width = body["length"], body["width"]
    placement = _place(ctx, d, vals, length, placed)
    road = placement[0] if placement is not None else None
    route = placement[3] if placement is not None else []
    if placement is not None and "goal" in vals and d.is_ego:
        info = ctx.road_info.get(placement[0])
        span = next(st.value.span for st in d.settings + d.block_settings if st.key == "goal")
        if route and info is not None and info.network is not None:
            # On a route the ego's station runs along the route: the goal is checked against its length.
            check_range(ctx, vals["goal"], 0.0, route_length(info.network, route, placement[1]), units.LENGTH,
                        "the goal (a station along the route)", span)
        elif info is not None:
            check_range(ctx, vals["goal"], 0.0, info.length_m, units.LENGTH, "the goal", span)
    if "goal" in vals and not d.is_ego:
        span = next(s.key_span for s in d.settings + d.block_settings if s.key == "goal")
        ctx.sink.warning("W0002", "only the ego has a goal", span)
    if d.vehicle in STATIC_KINDS:
        _check_static(ctx, d, vals)
    behaviors, sensors, stack = [], [], None
    stack_span: Span | None = None
    sensor_spans: dict[str, Span] = {}
    for c in d.clauses:
        plan = _check_clause(ctx, c, d, road)
        if plan is None:
            continue
        if c.keyword == "behavior":
            behaviors.append(plan)
        elif c.keyword == "sensor":
            if plan.name in sensor_spans:
                ctx.sink.error("E0102", f"sensor '{plan.name}' is given twice", c.name_span,
                               f"first given at {sensor_spans[plan.name]}")
                continue
            sensor_spans[plan.name] = c.name_span
            sensors.append(plan)
        elif c.keyword == "stack":
            if stack is not None:
                ctx.sink.error("E0102", "the ego has one stack", c.span, f"first given at {stack_span}")
                continue
            stack, stack_span = plan, c.span
    _check_lateral_conflicts(ctx, d)
    triggers = [t for t in (_lower_step(ctx, s, d, road) for s in d.steps) if t is not None]
    if is_scripted_ego(d) and not any(c.keyword == "stack" for c in d.clauses):
        # A scripted ego without a `stack` clause has no stack, so nothing reads sensors.
        for c in d.clauses:
            if c.keyword == "sensor":
                ctx.sink.error("E0204", "a scripted ego without a stack has no sensors", c.span,
                               "its behaviours and steps drive it; add a `stack` to run one open loop "
                               "on its sensors (its commands are recorded, not applied)")
        sensors = []
    elif d.is_ego:
        sensors = sensors or [DEFAULT_SENSOR]
        stack = stack or DEFAULT_STACK
        _check_stack_sensors(ctx, stack, sensors, stack_span or d.span)
        _check_stack_settings(ctx, stack, stack_span or d.span)
        _check_sensor_expectations(ctx, stack, sensors, sensor_spans, stack_span or d.span)
    if placement is None:
        return None
    _, lane, s, _ = placement
    return P.ActorPlan(
        name=d.name, vehicle=d.vehicle, road=road, lane=lane, s=s,
        speed=vals.get("speed", P.num(0.0)),
        length_m=length, width_m=width, height_m=body["height"], mass_kg=body["mass"], wheelbase_m=body["wheelbase"],
        behaviors=behaviors, triggers=triggers, sensors=sensors, stack=stack,
        goal_s=vals.get("goal"), mu=vals.get("mu"), offset=vals.get("offset"), route=route, yaw=vals.get("yaw"),
        ignore_lights=vals.get("at_red") == "run", reverse=vals.get("direction") == "reverse",
        stop_at_road_end=vals.get("at_road_end") == "stop")


def is_scripted_ego(d: ast.ActorDecl) -> bool:
    """An ego with a behaviour or a step: its script moves it, not its stack."""
    return d.is_ego and (bool(d.steps) or any(c.keyword == "behavior" for c in d.clauses))


def _check_static(ctx: Context, d: ast.ActorDecl, vals: dict) -> None:
    """A static object has no speed, behaviours or steps, and is not the ego."""
    if d.is_ego:
        ctx.sink.error("E0204", f"the ego cannot be a static {d.vehicle}", d.vehicle_span, "use `car` or `truck`")
        return
    moving = [c.span for c in d.clauses] + [s.span for s in d.steps]
    if moving:
        ctx.sink.error("E0204", f"a {d.vehicle} does not move: it takes no behaviours or steps", moving[0],
                       "use `car` for a vehicle that stops or starts")
    speed = const_value(vals["speed"]) if "speed" in vals else 0.0
    if speed != 0.0:
        span = next(st.value.span for st in d.settings + d.block_settings if st.key == "speed")
        ctx.sink.error("E0204", f"a {d.vehicle} does not move: its speed is 0", span)


def _check_stack_sensors(ctx: Context, stack: P.ClausePlan, sensors: list, span: Span) -> None:
    """A stack setting that reads a sensor the ego lacks (`perception camera` without a
    camera): the stack class says which sensors its settings need."""
    needs = getattr(STACKS.get(stack.name), "required_sensors", None)
    if needs is None:
        return
    words = {k: v for k, v in stack.settings.items() if isinstance(v, str)}
    for keyword in sorted(set(needs(words)) - {s.name for s in sensors}):
        ctx.sink.error("E0103", f"the ego's stack settings need a {keyword} sensor", span,
                       f"add e.g. `sensor {keyword}` to the ego")


def _check_stack_settings(ctx: Context, stack: P.ClausePlan, span: Span) -> None:
    """Settings whose form the stack class checks itself (`setting_problems`: the bridge's address)."""
    problems_of = getattr(STACKS.get(stack.name), "setting_problems", None)
    if problems_of is None:
        return
    words = {k: v for k, v in stack.settings.items() if isinstance(v, str)}
    for key, message in sorted(problems_of(words).items()):
        ctx.sink.error("E0204", f"the stack's {key}: {message}", span)


def _check_sensor_expectations(ctx: Context, stack: P.ClausePlan, sensors: list, spans: dict, span: Span) -> None:
    """A sensor unlike the one the stack's settings are made for (the learned detector on
    another lidar than it was trained on) still runs, but works worse: a warning."""
    mismatches = getattr(STACKS.get(stack.name), "sensor_mismatches", None)
    if mismatches is None:
        return
    words = {k: v for k, v in stack.settings.items() if isinstance(v, str)}
    for sensor in sensors:
        cls = SENSORS.get(sensor.name)
        if cls is None:
            continue
        values = {p.name: p.default for p in cls.params if isinstance(p.default, (int, float))}
        values.update({k: v.value for k, v in sensor.settings.items() if isinstance(v, P.Num)})
        dims = {p.name: p.dim for p in cls.params}
        wanted = [f"{key} {fmt(want, dims[key], 'deg' if dims[key] == units.ANGLE else None)}"
                  for key, want in mismatches(words, sensor.name, values)]
        if wanted:
            ctx.sink.warning("W0003", f"{words.get('perception', 'this')} perception is made for a "
                                      f"{sensor.name} with {', '.join(wanted)}", spans.get(sensor.name, span),
                             "it runs, but expect worse detection")


def _place(ctx: Context, d: ast.ActorDecl, vals: dict, length: float, placed: dict[str, P.ActorPlan]):
    """(road, lane, s) of an actor: absolute `on R lane L at S`, or relative to another actor."""
    along = [p for p in d.placements if p.kind in ("ahead", "behind")]
    lane_rel = [p for p in d.placements if p.kind.startswith("lane_")]
    for group, what in ((along, "position along the road"), (lane_rel, "lane")):
        if len(group) > 1:
            ctx.sink.error("E0102", f"the {what} of '{d.name}' is given twice", group[1].span)
            return None
    if along and "at" in vals:
        ctx.sink.error("E0102", f"'{d.name}' has both `at` and `{along[0].kind} ...`", along[0].span,
                       "give the position once")
        return None
    if lane_rel and "lane" in vals:
        ctx.sink.error("E0102", f"'{d.name}' has both `lane N` and `{_placement_text(lane_rel[0])}`",
                       lane_rel[0].span)
        return None
    refs = [p for p in along + lane_rel if p.actor in ctx.actors_ast]
    if len(refs) < len(along + lane_rel):
        return None  # unknown actor, already reported
    for p in refs:
        if p.actor not in placed:
            return None  # the reference failed to check (or a cycle): reported there
    road = vals.get("on")
    road_span = next((s.value.span for s in d.settings + d.block_settings if s.key == "on"), d.span)
    if road is not None and road not in ctx.roads_ast:
        ctx.sink.error("E0101", f"unknown road '{road}'", road_span, *suggest(road, ctx.roads_ast),
                       f"roads: {', '.join(sorted(ctx.roads_ast))}")
        return None
    for p in refs:
        other_road = placed[p.actor].road
        if road is None:
            road = other_road
        elif road != other_road:
            ctx.sink.error("E0204", f"'{d.name}' is on road '{road}' but placed relative to '{p.actor}' "
                           f"on road '{other_road}'", p.span, "relative placement works along one road")
            return None
    given = {st.key for st in d.settings + d.block_settings}
    if any(k in given and k not in vals for k in ("on", "lane", "at")):
        return None  # given but invalid: reported already
    missing = [k for k, ok in (("on", road is not None), ("lane", "lane" in vals or lane_rel or along),
                               ("at", "at" in vals or along)) if not ok]
    if missing:
        ctx.sink.error("E0105", f"'{d.name}' needs a position: {', '.join(missing)}", d.span,
                       "e.g. `on highway lane -1 at 20 m`, or relative: `ahead of lead 20 m`")
        return None
    # Lane: given, or that of a reference actor (shifted for left/right of).
    if "lane" in vals:
        lane = vals["lane"]
        lane_span = next(s.value.span for s in d.settings + d.block_settings if s.key == "lane")
    else:
        p = lane_rel[0] if lane_rel else along[0]
        lane = _lane_relative(p.kind, placed[p.actor].lane)
        lane_span = p.span
    route_ref = next((placed[p.actor] for p in refs if placed[p.actor].route), None)
    if along:
        p = along[0]
        other = placed[p.actor]
        dist = ctx.lowering().lower_value(p.distance, units.LENGTH, f"the distance {p.kind} '{p.actor}'")
        if dist is None:
            return None
        check_range(ctx, dist, 0.0, None, units.LENGTH, "the gap", p.distance.span)
        # The distance is a bumper-to-bumper gap, so half of both lengths is added; "ahead"
        # is in the other actor's driving direction (against s on a lane driven that way).
        half = E.Num(value=0.5 * (other.length_m + length))
        offset = E.Binary(op="+", left=dist, right=half)
        ahead = (p.kind == "ahead") == (_direction(ctx, other) > 0)
        s = E.Binary(op="+" if ahead else "-", left=other.s, right=offset)
        s_span = p.span
    else:
        s = vals["at"]
        s_span = next(st.value.span for st in d.settings + d.block_settings if st.key == "at")
    route: list[str] = []
    if d.route is not None or route_ref is not None:
        # An actor placed relative to one on a route shares that route (re-checked for its lane).
        spec = d.route if d.route is not None else ast.Route(refs[0].span, tuple(route_ref.route),
                                                              tuple(refs[0].span for _ in route_ref.route))
        got = check_route(ctx, spec, road, lane, s if not along else None, lane_span)
        if got is None:
            return None
        route, first_info = got
        if not along and first_info is not None:
            _check_on_road(ctx, d, road, lane, lane_span, s, s_span, first_info, route[0])
        return road, lane, s, route
    _check_on_road(ctx, d, road, lane, lane_span, s, s_span)
    return road, lane, s, route


def _direction(ctx: Context, actor: P.ActorPlan) -> int:
    """+1 if the actor's lane is driven along +s (OpenDRIVE: right-hand traffic drives
    negative lane ids along +s), -1 against; +1 when the lane depends on parameters."""
    lane = int_const(actor.lane)
    if lane is None or lane == 0:
        return 1
    info = ctx.road_info.get(actor.road)
    if info is not None and info.network is not None:
        road = info.network.road(actor.route[0] if actor.route else info.road_id)
        return road.travel_direction(lane)
    return 1 if lane < 0 else -1


def _placement_text(p: ast.Placement) -> str:
    return {"lane_of": f"lane of {p.actor}", "lane_left": f"lane left of {p.actor}",
            "lane_right": f"lane right of {p.actor}"}.get(p.kind, p.kind)


def _lane_relative(kind: str, lane):
    """The lane of another actor, or its left/right neighbour. OpenDRIVE ids grow to the
    left and skip 0, so left of -1 is 1: `L + 1 + max(0, 1 - |L + 1|)` (and mirrored)."""
    if kind in ("lane_of", "ahead", "behind"):
        return lane
    sign = 1.0 if kind == "lane_left" else -1.0
    shifted = E.Binary(op="+", left=lane, right=E.Num(value=sign))
    skip_zero = E.Call(fn="max", args=(E.Num(value=0.0), E.Binary(
        op="-", left=E.Num(value=1.0), right=E.Call(fn="abs", args=(shifted,)))))
    result = E.Binary(op="+", left=shifted, right=E.Binary(op="*", left=E.Num(value=sign), right=skip_zero))
    const = const_value(result)
    return E.Num(value=float(round(const))) if const is not None else result


def _check_on_road(ctx: Context, d: ast.ActorDecl, road: str, lane, lane_span: Span, s, s_span: Span,
                   info=None, map_road: str = "") -> None:
    info = info or ctx.road_info.get(road)
    if info is None:
        return
    where = f"road {map_road} of '{road}'" if map_road else f"'{road}'"
    check_range(ctx, s, 0.0, info.length_m, units.LENGTH, f"the position of '{d.name}' along {where}", s_span)
    lane_c = int_const(lane)
    s_c = const_value(s)
    lanes = info.lane_ids
    if info.network is not None and s_c is not None and 0.0 <= s_c <= info.length_m:
        # Lane sections renumber lanes: check the lanes where the actor starts.
        lanes = tuple(i for i in info.network.road(map_road or info.road_id).lane_ids(s_c) if i != 0)
    if lane_c is not None:
        if lane_c not in lanes:
            at = f" at {s_c:g} m" if s_c is not None and lanes != info.lane_ids else ""
            ctx.sink.error("E0301", f"{where} has no lane {lane_c}{at}" if map_road
                           else f"road '{road}' has no lane {lane_c}{at}", lane_span,
                           f"lanes of {where}{at}: {', '.join(str(i) for i in lanes)}",
                           "lane ids are negative right of the reference line (-1, -2, ...), positive left")
    else:
        got = value_range(lane, ctx.param_ranges)
        if got is not None and info.lane_ids:
            lo, hi = min(info.lane_ids), max(info.lane_ids)
            if got[0] < lo or got[1] > hi:
                ctx.sink.error("E0301", f"the lane of '{d.name}' can be outside the lanes of '{road}'", lane_span,
                               f"it spans [{got[0]:g}, {got[1]:g}]; lanes: {', '.join(str(i) for i in info.lane_ids)}")


def _check_lateral_conflicts(ctx: Context, d: ast.ActorDecl) -> None:
    lateral = [c for c in d.clauses if c.keyword == "behavior" and _channel(c.name) == "lateral"]
    if len(lateral) > 1:
        ctx.sink.warning("W0002", "two lane changes start at once; only the last one has an effect",
                         lateral[1].span, "order them with `sequence { ... }` or `at`/`after`")


def _channel(behavior: str) -> str | None:
    """The channel a behaviour drives (`Behavior.channel`: longitudinal or lateral)."""
    return getattr(BEHAVIORS.get(behavior), "channel", None)


CLAUSE_TABLES = {"behavior": BEHAVIORS, "sensor": SENSORS, "stack": STACKS}  # clause keyword: its registry


def _check_clause(ctx: Context, c: ast.Clause, actor: ast.ActorDecl, road: str | None) -> P.ClausePlan | None:
    table = CLAUSE_TABLES.get(c.keyword)
    if table is None:  # `light`: state changes of traffic lights live in `lights { }`
        ctx.sink.error("E0204", f"`{c.keyword}` steps belong in the `lights {{ }}` block", c.span,
                       "e.g. `lights { when distance(ego, car) < 30 m then light west state red }`")
        return None
    if c.keyword in ("sensor", "stack") and not actor.is_ego:
        ctx.sink.error("E0204", f"only the ego has a {c.keyword}", c.span,
                       "traffic agents follow behaviours")
        return None
    cls = table.get(c.name)
    if cls is None:
        ctx.sink.error("E0106", f"unknown {c.keyword} '{c.name}'", c.name_span, *suggest(c.name, table.names()),
                       f"{c.keyword}s: {', '.join(table.names())}")
        return None
    vals = check_settings(ctx, c.settings + c.block, cls.params, f"{c.keyword} '{c.name}'", c.span)
    if not _validate_clause(ctx, c, cls, vals):
        return None
    if c.keyword == "behavior" and getattr(cls, "channel", "") == "lateral" and "to" in vals \
            and any(p.name == "to" and p.kind == "int" for p in cls.params):  # a lane id (not an offset)
        _check_target_lane(ctx, c, vals["to"], road)
    for spec in cls.params:  # a `name` setting of a behaviour names another actor
        if c.keyword == "behavior" and spec.kind == "name" and isinstance(vals.get(spec.name), str):
            other = vals[spec.name]
            if other not in ctx.actors_ast or other == actor.name:
                span = next(st.value.span for st in c.settings + c.block if st.key == spec.name)
                pool = [a for a in ctx.actors_ast if a != actor.name]
                ctx.sink.error("E0101", f"unknown actor '{other}'" if other != actor.name
                               else f"'{other}' cannot {c.name} itself", span, *suggest(other, pool),
                               f"actors: {', '.join(sorted(pool))}")
                return None
    return P.ClausePlan(keyword=c.keyword, name=c.name, settings=vals)


def _validate_clause(ctx: Context, c: ast.Clause, cls, vals: dict) -> bool:
    return validate_settings(ctx, cls, vals, c.settings + c.block, c.span)


def _check_target_lane(ctx: Context, c: ast.Clause, lane, road: str | None) -> None:
    """A lane change must aim at a lane of the actor's road."""
    info = ctx.road_info.get(road or "")
    if info is None or not info.lane_ids:
        return
    span = next((st.value.span for st in c.settings + c.block if st.key == "to"), c.span)
    lane_c = int_const(lane)
    if lane_c is not None:
        if lane_c not in info.lane_ids:
            ctx.sink.error("E0301", f"road '{road}' has no lane {lane_c}", span,
                           f"lanes of '{road}': {', '.join(str(i) for i in info.lane_ids)}")
        return
    got = value_range(lane, ctx.param_ranges)
    if got is not None and (got[0] < min(info.lane_ids) or got[1] > max(info.lane_ids)):
        ctx.sink.error("E0301", f"the target lane can be outside the lanes of '{road}'", span,
                       f"it spans [{got[0]:g}, {got[1]:g}]; lanes: {', '.join(str(i) for i in info.lane_ids)}")


def _lower_step(ctx: Context, node, actor: ast.ActorDecl, road: str | None) -> P.TriggerPlan | None:
    """A step or group of an actor's block → TriggerPlan (groups become a step without
    a start condition that arms the group)."""
    if isinstance(node, ast.Clause):
        clause = _check_clause(ctx, node, actor, road)
        return P.TriggerPlan(clause=clause) if clause is not None else None
    if isinstance(node, ast.Group):
        group = _lower_group(ctx, node, actor, road)
        return P.TriggerPlan(group=group, label=node.label) if group is not None else None
    starts = lower_starts(ctx, node.starts)
    ok = starts.ok
    if starts.when is not None and starts.when.repeat is not None and isinstance(node.action, ast.Group):
        ctx.sink.error("E0204", "`repeat` starts one behaviour again, not a group", starts.nodes["when"].repeat.span,
                       "repeat the steps inside the group")
        ok = False
    if isinstance(node.action, ast.Group):
        group = _lower_group(ctx, node.action, actor, road)
        clause = None
        ok = ok and group is not None
    else:
        clause = _check_clause(ctx, node.action, actor, road)
        group = None
        ok = ok and clause is not None
    if not ok:
        return None
    return P.TriggerPlan(clause=clause, group=group, label=node.label, **starts.fields)


def _lower_group(ctx: Context, node: ast.Group, actor: ast.ActorDecl, road: str | None) -> P.GroupPlan | None:
    if not node.items:
        ctx.sink.error("E0103", f"empty `{node.mode}` block", node.span)
        return None
    steps = [_lower_step(ctx, item, actor, road) for item in node.items]
    if any(s is None for s in steps):
        return None
    return P.GroupPlan(mode=node.mode, steps=steps)
