"""One run (a `RunSpec`) as OpenSCENARIO XML 1.2 + OpenDRIVE + a side file.

Written with the `scenariogeneration` package (no hand-built XML). The mapping, in
short (docs/openscenario.md has the full table):

- actors -> `ScenarioObject`s (a `Vehicle`, or a `Pedestrian` for `pedestrian`), the
  bounding box centred on the entity's reference point (addt-dsl places an actor's
  centre); the initial lane position (`TeleportAction` to a `LanePosition`) and speed
  (`AbsoluteSpeedAction`, step) go into `Init`;
- behaviours -> one `Event` each in the actor's `Maneuver`: `cruise` and `brake` are
  `AbsoluteSpeedAction`s with linear dynamics at their acceleration (or their dynamics
  shape), a live `cruise` target `RelativeTargetSpeed`, `lane_change` and `cut_in`
  `AbsoluteLaneChangeAction`s (`RelativeLaneChangeAction` for `to_lane_of`) over their
  duration, `speed_profile` a `SpeedProfileAction`, `keep_gap` a
  `LongitudinalDistanceAction`, `synchronize` a `SynchronizeAction`, `trajectory` a
  `FollowTrajectoryAction` (polyline); routes are `AssignRouteAction`s and the
  `environment` an `EnvironmentAction` in `Init`; `idm`, `overtake`, `walk`
  and `cross` have no OpenSCENARIO action: they are `AssignControllerAction`s of a
  controller named `addt_<keyword>` whose properties are the settings;
- step start conditions -> the event's start trigger: `at T` / `after T` a
  `SimulationTimeCondition`, `s(A) > x` a `TraveledDistanceCondition`, `speed(A)`
  a `SpeedCondition`, `gap(A, B)` and `distance(A, B)` `RelativeDistanceCondition`s,
  `ttc(A, B)` a `TimeToCollisionCondition`, the distance to a point (the import's form of
  ReachPositionCondition) a `DistanceCondition`; `when C for D` a condition delay D; `and`
  within a condition group, `or`
  across groups; a formula with no such form becomes a `ParameterCondition` on a
  declared, never-set parameter `addt_condition_N`;
- traffic lights -> `RoadNetwork/TrafficSignals`: one `TrafficSignalController` per
  controller, phases green, yellow, red with each signal's lamp states (esmini's
  `on;off;off` strings, `LAMPS`); light steps -> events of an actor-less maneuver group
  (`TrafficSignalStateAction`s on the controller's signals, `program` a
  `TrafficSignalControllerAction`); `light(C) == S` -> a `TrafficSignalCondition` on C's
  first signal; inline `signal`s are written into the generated `.xodr` (ids 1, 2, ...);
- the duration -> the storyboard's stop trigger;
- what OpenSCENARIO cannot say (the ego's stack and sensors, goal, tyre friction,
  the fault schedule, oracles, step, seeds, script groups, exact behaviour settings
  and trigger formulas, `at_red run`) -> the side file `<stem>.addt.json` (named by the declared
  parameter `addt_sidecar`), listed in `Export.carried`. `openscenario/sidefile.py` defines it; import reads it.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

from scenariogeneration import xosc

from addt_dsl import expr as E
from addt_dsl import units
from addt_dsl.atomic import write_text
from addt_dsl.expr import eval_param_expr
from addt_dsl.interop.xodr_export import ExportError, creation_date, road_file, xml_text
from addt_dsl.plan import LIGHT_PROGRAM, LIGHT_STATES, ActorPlan, ClausePlan, RunSpec, TriggerPlan, resolve_settings
from addt_dsl.printer import format_expr, pin_spec
from addt_dsl.printer.expr import dim_of_name
from addt_dsl.specs.behaviors import PEAK_CURVATURE
from addt_dsl.interop.openscenario.sidefile import CONTROLLER_PREFIX, SIDECAR_FORMAT, SIDECAR_PARAM
from addt_dsl.registry import BEHAVIORS
from addt_dsl.runtime.environment import Light
from addt_dsl.road.route import resolve_route
from addt_dsl.road.roadspec import build_network
from addt_dsl.vehicles import VEHICLES

OSC_MINOR = 2  # OpenSCENARIO 1.2
RULES = {"<": xosc.Rule.lessThan, "<=": xosc.Rule.lessOrEqual, ">": xosc.Rule.greaterThan,
         ">=": xosc.Rule.greaterOrEqual, "==": xosc.Rule.equalTo, "!=": xosc.Rule.notEqualTo}
FLIP = {"<": ">", "<=": ">=", ">": "<", ">=": "<=", "==": "==", "!=": "!="}
CATEGORY = {"car": xosc.VehicleCategory.car, "truck": xosc.VehicleCategory.truck,
            "cyclist": xosc.VehicleCategory.bicycle}
# esmini's lamps of an OpenDRIVE traffic light, top to bottom, by `type` or `type.subtype`
# (its RoadManager traffic_light_type_map); a TrafficSignalState's `state` gives each lamp's
# mode in this order ("on;off;off": red). Other types: three lamps, red, yellow, green.
LAMPS = {"1000001": ("red", "yellow", "green"), "1000011": ("red", "yellow", "green"),
         "1000013": ("red", "yellow", "green"), "1000002": ("red", "green"),
         "1000002.30": ("red", "red", "green"), "1000009.10": ("red", "yellow"), "1000009.20": ("yellow", "green")}
LIGHTS_GROUP = "addt_lights"  # the maneuver group (no actors) of the light steps
ENVIRONMENT_GROUP = "addt_environment_changes"  # ... and of the environment's changes
VARIABLE_GROUP = "addt_variable_steps"  # ... and of the steps that set scenario variables
__all__ = ["Export", "ExportError", "export_run", "SIDECAR_FORMAT", "SIDECAR_PARAM", "CONTROLLER_PREFIX", "LAMPS",
           "LIGHTS_GROUP", "lamps_of", "lamp_state", "state_of_lamps"]


# The OpenSCENARIO elements an export writes (schema paths as docs/osc_schema.py names them),
# each with the `.addt` constructs that write it: the export column of docs/openscenario.md's
# coverage table. tests/unit/interop/test_export_coverage.py exports a corpus and checks that
# it writes exactly these.
EXPORTED: dict[str, str] = {
    "PrivateAction/TeleportAction": "every actor's start (Init); `teleport` (a RoadPosition)",
    "PrivateAction/LongitudinalAction/SpeedAction": "start speeds; `cruise`, `brake` (absolute or relative target)",
    "PrivateAction/LongitudinalAction/SpeedProfileAction": "`speed_profile`",
    "PrivateAction/LongitudinalAction/LongitudinalDistanceAction": "`keep_gap`",
    "PrivateAction/LateralAction/LaneChangeAction": "`lane_change` (absolute, or to another actor's lane)",
    "PrivateAction/LateralAction/LaneOffsetAction": "`lane_offset`",
    "PrivateAction/SynchronizeAction": "`synchronize`",
    "PrivateAction/RoutingAction/AssignRouteAction": "`route ...` of an actor",
    "PrivateAction/RoutingAction/FollowTrajectoryAction": "`trajectory` (road or world coordinates)",
    "PrivateAction/ControllerAction/AssignControllerAction": "behaviours without an OpenSCENARIO action (`idm`, "
                                                            "`overtake`, `walk`, ...): a named controller",
    "PrivateAction/VisibilityAction": "the anchor of a `sequence`/`parallel` group (no effect)",
    "GlobalAction/EnvironmentAction": "`environment { }` and its steps",
    "GlobalAction/VariableAction/SetAction": "`variables { }`: a step that sets a variable",
    "GlobalAction/InfrastructureAction/TrafficSignalAction/TrafficSignalStateAction": "`light C state S`",
    "GlobalAction/InfrastructureAction/TrafficSignalAction/TrafficSignalControllerAction": "`light C state program`",
    "ByValueCondition/SimulationTimeCondition": "`at T`, `after T`, the duration",
    "ByValueCondition/StoryboardElementStateCondition": "`started(...)`, `ended(...)`, steps after others",
    "ByValueCondition/ParameterCondition": "a condition with no OpenSCENARIO form (a parameter the side file sets)",
    "ByValueCondition/TrafficSignalCondition": "`light(C) == S`",
    "ByValueCondition/VariableCondition": "`var(NAME)` compared",
    "ByEntityCondition/EntityCondition/RelativeDistanceCondition": "`distance(a, b)`, `gap(a, b)` compared",
    "ByEntityCondition/EntityCondition/SpeedCondition": "`speed(a)` compared",
    "ByEntityCondition/EntityCondition/AccelerationCondition": "`accel(a)` compared",
    "ByEntityCondition/EntityCondition/TimeHeadwayCondition": "`gap(a, b) OP T * speed(a)` (the import's form)",
    "ByEntityCondition/EntityCondition/TimeToCollisionCondition": "`ttc(a, b)` compared",
    "ByEntityCondition/EntityCondition/TraveledDistanceCondition": "`travelled(a)` compared",
    "ByEntityCondition/EntityCondition/OffroadCondition": "`road_edge(a) < 0 m`",
    "ByEntityCondition/EntityCondition/EndOfRoadCondition": "`road_end(a) <= 0 m` (`for D`: its duration)",
    "ByEntityCondition/EntityCondition/DistanceCondition": (
        "`(x(a) - X) * (x(a) - X) + (y(a) - Y) * (y(a) - Y) < R * R` (the import's form of ReachPositionCondition: "
        "the distance to a WorldPosition, reference point)"),
    "LanePosition": "start positions",
    "RoadPosition": "`trajectory s [...] t [...]`, `synchronize` targets",
    "WorldPosition": "`trajectory x [...] y [...]`",
}


def lamps_of(sig_type: str, subtype: str = "") -> tuple[str, ...]:
    """The lamp colours of an OpenDRIVE signal of this type and subtype, top to bottom."""
    if subtype not in ("", "-1") and f"{sig_type}.{subtype}" in LAMPS:
        return LAMPS[f"{sig_type}.{subtype}"]
    return LAMPS.get(sig_type, LAMPS["1000001"])


def lamp_state(lamps: tuple[str, ...], state: str) -> str:
    """The lamp modes that show `state` (green, yellow, red): its lamp on, the others off; a
    light without that colour shows the nearest one it has (red for yellow, else all off)."""
    colour = state if state in lamps else ("red" if state == "yellow" and "red" in lamps else None)
    first = lamps.index(colour) if colour is not None else -1
    return ";".join("on" if i == first else "off" for i in range(len(lamps)))


def state_of_lamps(lamps: tuple[str, ...], text: str) -> str | None:
    """green, yellow or red from a state string: lamp modes (`off;off;on`, `flashing`
    counts as on) or a colour word (`Red`, `amber`); None when it shows none or two."""
    word = text.strip().lower()
    if word in ("green", "yellow", "red", "amber"):
        return "yellow" if word == "amber" else word
    modes = [m.strip().lower() for m in text.split(";") if m.strip()]
    if len(modes) != len(lamps):
        return None
    on = {lamps[i] for i, m in enumerate(modes) if m in ("on", "flashing")}
    return on.pop() if len(on) == 1 else None


@dataclass
class Export:
    """What `export_run` wrote and what only the side file carries."""

    xosc_path: Path
    xodr_path: Path
    sidecar_path: Path
    carried: list[str] = field(default_factory=list)  # one line per item OpenSCENARIO cannot hold


class _Run:
    """The concrete values of one run, and the mapping state."""

    def __init__(self, spec: RunSpec, road_ids: dict[str, str]):
        self.spec = spec
        self.plan = spec.plan
        self.params = spec.params
        self.road_ids = road_ids
        self.carried: list[str] = []
        self.behaviors: dict[str, dict] = {}  # event name -> exact clause (side file)
        self.conditions: dict[str, dict] = {}  # placeholder parameter -> exact formula (side file)
        self.holds: dict[str, float] = {}  # event -> `when C for D` hold [s] (written as a condition delay)
        self.groups: dict[str, list] = {}
        self.group_events: set[str] = set()  # events that belong to a group (the side file has its steps)
        self.event_names: list[str] = []
        self.placeholders: list[str] = []
        self.s0 = {a.name: self.num(a.s) for a in self.plan.actors()}
        self.v0 = {a.name: self.num(a.speed) for a in self.plan.actors()}
        self.t0 = {a.name: self.num(a.offset) if a.offset is not None else 0.0 for a in self.plan.actors()}
        self.by_name = {a.name: a for a in self.plan.actors()}
        self.names: set[str] = set()
        self.along = {a.name for a in self.plan.actors() if _along_s(self.plan, a, int(round(self.num(a.lane))))}
        self.controllers = {c.name: c for c in self.plan.controllers}
        self.signal_ids: dict[str, str] = {}  # inline signal name -> its id in the generated .xodr
        self.signal_lamps: dict[str, tuple[str, ...]] = {}  # map signal id -> lamp colours
        self.light_steps: dict[str, dict] = {}  # event -> exact light clause (side file)
        # `actor.label` -> the named step whose state `started(...)`/`ended(...)` read; the event that
        # stands for it is known once that step is exported, so its conditions are filled in then.
        self.labels = {f"{a.name}.{tr.label}": tr for a in self.plan.actors() for tr in _all_steps(a.triggers)
                       if tr.label}
        self.label_events: dict[str, str] = {}  # `actor.label` -> its event (a group's: its anchor)
        self.state_refs: list[tuple[xosc.StoryboardElementStateCondition, str]] = []

    def signal_id(self, sid: str) -> str:
        return self.signal_ids.get(sid, sid)

    def lamp_state(self, sid: str, state: str) -> str:
        return lamp_state(self.signal_lamps.get(self.signal_id(sid), LAMPS["1000001"]), state)

    def num(self, e) -> float:
        return float(eval_param_expr(e, self.params))

    def unique(self, base: str) -> str:
        name, i = base, 2
        while name in self.names:
            name, i = f"{base}_{i}", i + 1
        self.names.add(name)
        return name


def _all_steps(steps):
    for tr in steps:
        yield tr
        if tr.group is not None:
            yield from _all_steps(tr.group.steps)


# A step state as an event state: `started` when the event starts; `ended` when its actions end.
STEP_STATES = {"started": xosc.StoryboardElementState.startTransition,
               "ended": xosc.StoryboardElementState.endTransition}
# `started(A.step) > 0 and not ended(A.step) > 0` in one conjunction (`_running`).
RUNNING = xosc.StoryboardElementState.runningState


def _state_condition(run: _Run, fn: str, key: str, op: str, value: float, name: str):
    """`started(A.step) > 0` / `ended(A.step) > 0` as a StoryboardElementStateCondition on the
    step's event, or None where the comparison is not the state itself or the step has no one event
    (a group's end, a group without an anchor event)."""
    step = run.labels.get(key)
    if step is None or (fn not in STEP_STATES and fn != "running"):
        return None
    truth = {v: {"<": v < value, "<=": v <= value, ">": v > value, ">=": v >= value, "==": v == value,
                 "!=": v != value}.get(op) for v in (0.0, 1.0)}
    if truth != {0.0: False, 1.0: True}:  # a state signal is 0 or 1: only `state is true` has this form
        return None
    if step.group is not None and (fn != "started" or (step.at_s is None and step.after_s is None
                                                        and step.condition is None)):
        return None
    cond = xosc.StoryboardElementStateCondition(xosc.StoryboardElementType.event, key,
                                                RUNNING if fn == "running" else STEP_STATES[fn])
    run.state_refs.append((cond, key))
    return xosc.ValueTrigger(name, 0, xosc.ConditionEdge.none, cond)


# ---------------------------------------------------------------- entities

def _entity(a: ActorPlan):
    height = a.height_m if a.height_m is not None else VEHICLES[a.vehicle].height_m
    box = xosc.BoundingBox(a.width_m, a.length_m, height, 0.0, 0.0, height / 2)
    if a.vehicle == "pedestrian":
        return xosc.Pedestrian(a.name, 80.0, xosc.PedestrianCategory.pedestrian, box, model=a.vehicle)
    if a.vehicle == "obstacle":
        return xosc.MiscObject(a.name, a.mass_kg, xosc.MiscObjectCategory.obstacle, box)
    front = xosc.Axle(0.5, 0.7, a.width_m * 0.85, a.wheelbase_m / 2, 0.35)
    rear = xosc.Axle(0.0, 0.7, a.width_m * 0.85, -a.wheelbase_m / 2, 0.35)
    return xosc.Vehicle(a.name, CATEGORY[a.vehicle], box, front, rear, 70.0, 10.0, 12.0, mass=a.mass_kg)


def _position(run: _Run, a: ActorPlan) -> xosc.LanePosition:
    lane = int(round(run.num(a.lane)))
    # The language's offset is to the driver's left; OpenSCENARIO's along the road's t.
    offset = (run.num(a.offset) if a.offset is not None else 0.0) * _first_way(run.plan, a, lane)
    road_id = a.route[0] if a.route else run.road_ids[a.road]
    s = run.num(a.s)  # `at S` is a station of the first road, on a route too (only `s(A)` runs along it)
    if a.yaw is not None or a.reverse:  # both languages face an entity along its lane's driving direction
        h = (run.num(a.yaw) if a.yaw is not None else 0.0) + (math.pi if a.reverse else 0.0)
        orientation = xosc.Orientation(h=h, reference=xosc.ReferenceContext.relative)
        return xosc.LanePosition(s, offset, str(lane), road_id, orientation)
    return xosc.LanePosition(s, offset, str(lane), road_id)


def _first_way(plan, a: ActorPlan, lane: int) -> int:
    """+1 if the actor starts driving towards +s of its first road, -1 against."""
    road = plan.road(a.road)
    way = -1 if a.reverse else 1
    if road.source != "xodr":
        return way if lane < 0 else -way
    network = build_network([road])[a.road]
    first = a.route[0] if a.route else (road.xodr_road_id or next(iter(network.roads)))
    return network.road(first).travel_direction(lane) * way


def _along_s(plan, a: ActorPlan, lane: int) -> bool:
    """Whether the actor moves towards +s (no route, a lane driven along s)."""
    if a.route:
        return False
    road = plan.road(a.road)
    way = -1 if a.reverse else 1
    if road.source != "xodr":
        return lane * way < 0
    network = build_network([road])[a.road]
    return network.road(road.xodr_road_id or next(iter(network.roads))).travel_direction(lane) * way > 0


# ---------------------------------------------------------------- behaviours

# addt-dsl shape -> OpenSCENARIO 1.2 shape (1.2 has no quintic: the nearest is cubic)
OSC_SHAPE = {"step": xosc.DynamicsShapes.step, "linear": xosc.DynamicsShapes.linear,
             "cubic": xosc.DynamicsShapes.cubic, "sinusoidal": xosc.DynamicsShapes.sinusoidal,
             "quintic": xosc.DynamicsShapes.cubic}


def _speed_action(target: float, rate: float):
    return xosc.AbsoluteSpeedAction(target, xosc.TransitionDynamics(
        xosc.DynamicsShapes.linear, xosc.DynamicsDimension.rate, max(rate, 1e-3)))


def _speed_dynamics(shape: str, rate: float, duration: float | None,
                    distance: float | None = None) -> xosc.TransitionDynamics:
    """A shaped speed change. Without a duration or distance addt-dsl takes PEAK_SLOPE *
    |dv| / rate: `rate` is the peak rate of change, as esmini reads OpenSCENARIO's `rate`
    (TransitionDynamics::GetTargetParamValByPrimPeak)."""
    if shape == "step":
        return xosc.TransitionDynamics(xosc.DynamicsShapes.step, xosc.DynamicsDimension.time, 0.0)
    if duration is not None:
        return xosc.TransitionDynamics(OSC_SHAPE[shape], xosc.DynamicsDimension.time, max(duration, 0.0))
    if distance is not None:
        return xosc.TransitionDynamics(OSC_SHAPE[shape], xosc.DynamicsDimension.distance, max(distance, 0.0))
    return xosc.TransitionDynamics(OSC_SHAPE[shape], xosc.DynamicsDimension.rate, max(rate, 1e-3))


def _relative_speed(node) -> tuple[str, float, str] | None:
    """`k * speed(X)`, `speed(X) * k`, `speed(X) +/- c`, `speed(X)` as (X, value, kind)."""
    def actor(n):
        sig = _signal(n)
        return sig[1][0] if sig is not None and sig[0] == "speed" and len(sig[1]) == 1 else None

    def const(n):
        return None if E.signals_used(n) else _try_float(n)

    if actor(node) is not None:
        return actor(node), 0.0, "delta"
    if isinstance(node, E.Binary) and node.op == "*":
        for a, b in ((node.left, node.right), (node.right, node.left)):
            if actor(a) is not None and const(b) is not None:
                return actor(a), const(b), "factor"
    if isinstance(node, E.Binary) and node.op in ("+", "-"):
        if actor(node.left) is not None and const(node.right) is not None:
            return actor(node.left), const(node.right) * (1.0 if node.op == "+" else -1.0), "delta"
        if node.op == "+" and actor(node.right) is not None and const(node.left) is not None:
            return actor(node.right), const(node.left), "delta"
    return None


def _try_float(node) -> float | None:
    try:
        return float(eval_param_expr(node, {}))
    except (KeyError, ValueError, ArithmeticError, TypeError):
        return None


def _cruise(run, actor, s):
    live = s["speed"]
    if not isinstance(live, float):  # a live target: `1.2 * speed(ego)`
        rel = _relative_speed(live)
        if rel is None:
            # No OpenSCENARIO target: a controller whose `speed` property is the expression (JSON).
            return _controller("cruise")(run, actor, {**s, "speed": live.model_dump(mode="json")})
        other, value, kind = rel
        dyn = _speed_dynamics(s["shape"], s["accel"], s["duration"], s["distance"])
        valuetype = xosc.SpeedTargetValueType.factor if kind == "factor" else xosc.SpeedTargetValueType.delta
        return [xosc.RelativeSpeedAction(value, other, dyn, valuetype, continuous=True)], True
    rate = s["accel"] if s["speed"] >= run.v0[actor] else s["decel"]
    if s["shape"] == "linear" and s["duration"] is None and s["distance"] is None:
        return [_speed_action(s["speed"], rate)], True
    return [xosc.AbsoluteSpeedAction(s["speed"], _speed_dynamics(s["shape"], rate, s["duration"],
                                                                 s["distance"]))], True


def _brake(run, actor, s):
    return [_speed_action(s["to_speed"], s["decel"])], True


def _lane_change(run, actor, s):
    dyn = xosc.TransitionDynamics(OSC_SHAPE[s["shape"]], xosc.DynamicsDimension.time, s["duration"])
    if s["shape"] == "quintic" or s["shape"] not in OSC_SHAPE:
        run.carried.append(f"{actor}: lane change shape {s['shape']} written as cubic (OpenSCENARIO 1.2 has no "
                           "quintic; exact in the side file)")
    if s.get("to_lane_of"):
        return [xosc.RelativeLaneChangeAction(int(round(s.get("lanes") or 0)), s["to_lane_of"], dyn)], True
    return [xosc.AbsoluteLaneChangeAction(int(round(s["to"])), dyn)], True


def _lane_offset(run, actor, s):
    shape = "cubic" if s["shape"] == "quintic" else s["shape"]
    if s["shape"] == "quintic":
        run.carried.append(f"{actor}: lane offset shape quintic written as cubic (exact in the side file)")
    accel = s["max_lat_accel"]
    if accel is None:  # OpenSCENARIO times a lane offset by its peak lateral acceleration only
        change = abs(s["to"])
        accel = max(PEAK_CURVATURE.get(shape, 6.0) * change / max(s["duration"], 1e-3) ** 2, 0.01)
        run.carried.append(f"{actor}: lane offset over {s['duration']:g} s written as maxLateralAcc "
                           f"{accel:.4g} m/s^2 (the time from the lane's centre; exact in the side file)")
    # esmini's value: away from the reference line, by the sign of the lane id (the lane
    # the actor starts in; a lane changed before the offset is in the side file).
    lane = int(round(run.num(run.by_name[actor].lane)))
    value = s["to"] * (1.0 if lane > 0 else -1.0)
    return [xosc.AbsoluteLaneOffsetAction(value, OSC_SHAPE[shape], accel, continuous=False)], True


def _speed_profile(run, actor, s):
    # OpenSCENARIO entry times are durations from the previous entry (the first: from the start).
    times = list(s["times"])
    deltas = [times[0]] + [b - a for a, b in zip(times, times[1:])]
    if s["shape"] != "linear":
        run.carried.append(f"{actor}: speed profile shape {s['shape']} (SpeedProfileAction interpolates "
                           "linearly in `position` mode; exact in the side file)")
    if s.get("mode") == "follow":
        # An unset limit is left out: esmini reads the vehicle's Performance there (rates: unlimited).
        limits = {arg: s[name] for arg, name in (
            ("max_acceleration", "accel"), ("max_deceleration", "decel"), ("max_acceleration_rate", "accel_rate"),
            ("max_deceleration_rate", "decel_rate"), ("max_speed", "max_speed")) if s.get(name) is not None}
        if len(limits) < 5:
            run.carried.append(f"{actor}: speed profile limits left unset (unlimited) are the vehicle's "
                               "Performance in esmini")
        return [xosc.SpeedProfileAction(list(s["speeds"]), xosc.FollowingMode.follow, deltas,
                                        xosc.DynamicsConstraints(**limits) if limits else None)], True
    return [xosc.SpeedProfileAction(list(s["speeds"]), xosc.FollowingMode.position, deltas)], True


def _road_of(run, actor: str) -> str:
    a = run.by_name[actor]
    return a.route[0] if a.route else run.road_ids[a.road]


def _synchronize(run, actor, s):
    master = run.by_name[s["master"]]
    master_pos = xosc.LanePosition(s["master_at"], 0.0, str(int(round(run.num(master.lane)))),
                                   _road_of(run, s["master"]))
    target_s = s["target_s"] if s["target_s"] is not None else run.s0[actor]
    target_t = s["target_t"] if s["target_t"] is not None else run.t0[actor]
    final = s["final_speed"]
    if final is not None and not isinstance(final, float):  # live: `speed(master) - 3 m/s`
        rel = _relative_speed(final)
        if rel is None or rel[0] != s["master"]:
            # No OpenSCENARIO final speed: a controller whose `final_speed` property is the expression.
            return _controller("synchronize")(run, actor, {**s, "final_speed": final.model_dump(mode="json")})
        kind = xosc.SpeedTargetValueType.factor if rel[2] == "factor" else xosc.SpeedTargetValueType.delta
        final = xosc.RelativeSpeedToMaster(rel[1], kind)
    elif final is not None:
        final = xosc.AbsoluteSpeed(final)
    action = xosc.SynchronizeAction(s["master"], master_pos, xosc.RoadPosition(target_s, target_t,
                                                                               _road_of(run, actor)),
                                    target_tolerance_master=s["master_tolerance"] or None,
                                    target_tolerance=s["tolerance"] or None, final_speed=final)
    extra = [k for k in ("heading", "max_speed") if s.get(k) is not None and k in s]
    run.carried.append(f"{actor}: synchronize {', '.join(extra)} and rate limits (side file)")
    return [action], True


def _trajectory(run, actor, s):
    if s["s"] is not None:
        road = _road_of(run, actor)
        positions = [xosc.RoadPosition(ps, pt, road) for ps, pt in zip(s["s"], s["t"])]
    else:
        positions = [xosc.WorldPosition(px, py) for px, py in zip(s["x"], s["y"])]
    times = list(s["times"]) if s["times"] is not None else []
    traj = xosc.Trajectory(run.unique(f"{actor}_trajectory"), False)
    traj.add_shape(xosc.Polyline(times, positions))
    if times:  # vertex times from the start of the action
        follow = xosc.FollowTrajectoryAction(traj, xosc.FollowingMode.position, xosc.ReferenceContext.relative,
                                             1.0, 0.0)
        return [follow], True
    follow = xosc.FollowTrajectoryAction(traj, xosc.FollowingMode.position)
    # No times: the trajectory is driven at `speed`, a speed action in the same event.
    return [follow, _speed_action(s["speed"], s["accel"] if s["speed"] >= run.v0[actor] else s["decel"])], True


def _teleport(run, actor, s):
    # OpenDRIVE road coordinates of the road it is on, as the language's `teleport`.
    return [xosc.TeleportAction(xosc.RoadPosition(s["s"], s["t"], _road_of(run, actor)))], True


def _keep_gap(run, actor, s):
    side = (xosc.LongitudinalDisplacement.trailingReferencedEntity if s["side"] == "behind"
            else xosc.LongitudinalDisplacement.leadingReferencedEntity)
    return [xosc.LongitudinalDistanceAction(s["target"], freespace=True, continuous=True,
                                            max_acceleration=s["accel"], max_deceleration=s["decel"],
                                            distance=s["distance"], timeGap=s["time_gap"],
                                            displacement=side)], True


def _controller(keyword: str):
    def make(run, actor, s):
        props = xosc.Properties()
        for key, value in s.items():
            if value is None:
                continue
            props.add_property(key, json.dumps(value) if not isinstance(value, str) else value)
        ctrl = xosc.Controller(f"{CONTROLLER_PREFIX}{keyword}", props)
        return [xosc.AssignControllerAction(ctrl, activateLateral=True, activateLongitudinal=True)], False
    return make


# keyword -> (run, actor, resolved settings) -> (OpenSCENARIO actions, whether they are standard actions)
ACTIONS = {"cruise": _cruise, "brake": _brake, "lane_change": _lane_change, "cut_in": _lane_change,
           "lane_offset": _lane_offset,
           "speed_profile": _speed_profile, "synchronize": _synchronize, "trajectory": _trajectory,
           "keep_gap": _keep_gap, "teleport": _teleport,
           "idm": _controller("idm"), "overtake": _controller("overtake"), "walk": _controller("walk"),
           "cross": _controller("cross")}


# ---------------------------------------------------------------- conditions

def _signal(node) -> tuple[str, list[str]] | None:
    if not isinstance(node, E.Signal) or not node.name.endswith(")") or "(" not in node.name:
        return None
    fn, args = node.name[:-1].split("(", 1)
    return fn, [x.strip() for x in args.split(",")]


def _const(run: _Run, node) -> float | None:
    if E.signals_used(node):
        return None
    try:
        return float(eval_param_expr(node, run.params))
    except (KeyError, ValueError, ArithmeticError):
        return None


def _abs_distance(run: _Run, node, value, name: str):
    """`abs(gap(A, B) + H) OP D`, H half of both lengths (the importer's form of esmini's absolute
    longitudinal distance between reference points) as that RelativeDistanceCondition, or None."""
    if not (isinstance(node.left, E.Call) and node.left.fn == "abs" and isinstance(node.left.args[0], E.Binary)
            and node.left.args[0].op == "+" and isinstance(node.left.args[0].right, E.Num) and value is not None):
        return None
    sig = _signal(node.left.args[0].left)
    if sig is None or sig[0] != "gap" or len(sig[1]) != 2 or not all(a in run.by_name for a in sig[1]):
        return None
    a, b = (run.by_name[x] for x in sig[1])
    if abs(node.left.args[0].right.value - 0.5 * (a.length_m + b.length_m)) > 1e-9:
        return None
    cond = xosc.RelativeDistanceCondition(value, RULES[node.op], xosc.RelativeDistanceType.longitudinal, b.name,
                                          alongroute=False, freespace=False,
                                          coordinate_system=xosc.CoordinateSystem.road)
    return xosc.EntityTrigger(name, 0, xosc.ConditionEdge.none, cond, a.name)


def _headway(run: _Run, node, name: str):
    """`gap(A, B) OP T * speed(A)` (free space) or `... OP T * speed(A) + -H`, H half of both
    lengths (between reference points): the importer's form of a TimeHeadwayCondition, or None."""
    gap, right, free = _signal(node.left), node.right, True
    if isinstance(right, E.Binary) and right.op == "+" and isinstance(right.right, E.Num):
        right, half, free = right.left, -right.right.value, False
    if gap is None or gap[0] != "gap" or len(gap[1]) != 2 or not all(a in run.by_name for a in gap[1]) \
            or not (isinstance(right, E.Binary) and right.op == "*") or _signal(right.right) != ("speed", gap[1][:1]):
        return None
    a, b = (run.by_name[x] for x in gap[1])
    value = _const(run, right.left)
    if value is None or (not free and abs(half - 0.5 * (a.length_m + b.length_m)) > 1e-9):
        return None
    cond = xosc.TimeHeadwayCondition(b.name, value, RULES[node.op], alongroute=False, freespace=free,
                                     distance_type=xosc.RelativeDistanceType.longitudinal,
                                     coordinate_system=xosc.CoordinateSystem.road)
    return xosc.EntityTrigger(name, 0, xosc.ConditionEdge.none, cond, a.name)


def _to_point(run: _Run, node, name: str):
    """`(x(A) - X) * (x(A) - X) + (y(A) - Y) * (y(A) - Y) OP R * R` (the importer's form of a
    ReachPositionCondition and of a DistanceCondition to a position) as a DistanceCondition:
    the Euclidean distance of A's reference point to the point (X, Y), OP R, or None.
    OpenSCENARIO 1.2 deprecates ReachPositionCondition for DistanceCondition (and the export
    writes 1.2); esmini reads `freespace="false"` `euclidianDistance` as exactly this distance."""
    def square(term):  # (sig - C) * (sig - C) -> (signal, C)
        if not (isinstance(term, E.Binary) and term.op == "*" and term.left == term.right
                and isinstance(term.left, E.Binary) and term.left.op == "-"):
            return None
        sig, value = _signal(term.left.left), _const(run, term.left.right)
        return None if sig is None or value is None or len(sig[1]) != 1 else (sig, value)
    left, right = node.left, node.right
    if not (isinstance(left, E.Binary) and left.op == "+" and isinstance(right, E.Binary) and right.op == "*"
            and right.left == right.right):
        return None
    sx, sy, radius = square(left.left), square(left.right), _const(run, right.left)
    if sx is None or sy is None or radius is None or radius < 0 or sx[0][0] != "x" or sy[0][0] != "y" \
            or sx[0][1] != sy[0][1] or sx[0][1][0] not in run.by_name:
        return None
    cond = xosc.DistanceCondition(radius, RULES[node.op], xosc.WorldPosition(sx[1], sy[1]), alongroute=False,
                                  freespace=False, distance_type=xosc.RelativeDistanceType.euclidianDistance,
                                  coordinate_system=xosc.CoordinateSystem.entity)
    return xosc.EntityTrigger(name, 0, xosc.ConditionEdge.none, cond, sx[0][1][0])


def _compare(run: _Run, node, name: str):
    """One comparison `signal op constant` as an OpenSCENARIO condition, or None."""
    if not isinstance(node, E.Binary) or node.op not in RULES:
        return None
    point = _to_point(run, node, name) if isinstance(node.left, E.Binary) and node.left.op == "+" else None
    if point is not None:
        return point
    if isinstance(node.left, E.Call):
        return _abs_distance(run, node, _const(run, node.right), name)
    if E.signals_used(node.right):
        return _headway(run, node, name)
    op, sig, value = node.op, _signal(node.left), _const(run, node.right)
    if sig is None:
        op, sig, value = FLIP[node.op], _signal(node.right), _const(run, node.left)
    if sig is None or value is None:
        return None
    fn, args = sig
    if fn in STEP_STATES and len(args) == 1:
        return _state_condition(run, fn, args[0], op, value, name)
    rule = RULES[op]
    if fn == "s" and op in (">", ">=") and len(args) == 1 and args[0] in run.along:
        cond = xosc.TraveledDistanceCondition(max(0.0, value - run.s0[args[0]]))
        return xosc.EntityTrigger(name, 0, xosc.ConditionEdge.none, cond, args[0])
    if fn == "speed" and len(args) == 1:
        return xosc.EntityTrigger(name, 0, xosc.ConditionEdge.none, xosc.SpeedCondition(value, rule), args[0])
    if fn == "accel" and len(args) == 1 and op != "!=":
        return xosc.EntityTrigger(name, 0, xosc.ConditionEdge.none, xosc.AccelerationCondition(value, rule),
                                  args[0])
    if fn in ("gap", "distance") and len(args) == 2:
        kind = xosc.RelativeDistanceType.longitudinal if fn == "gap" else xosc.RelativeDistanceType.euclidianDistance
        cond = xosc.RelativeDistanceCondition(value, rule, kind, args[1], alongroute=False, freespace=fn == "gap",
                                              coordinate_system=xosc.CoordinateSystem.road if fn == "gap"
                                              else xosc.CoordinateSystem.entity)
        return xosc.EntityTrigger(name, 0, xosc.ConditionEdge.none, cond, args[0])
    if fn == "light" and len(args) == 1 and op == "==" and args[0] in run.controllers:
        state = next((k for k, code in LIGHT_STATES.items() if code == value), None)
        if state is None or not run.controllers[args[0]].signals:
            return None
        sid = run.controllers[args[0]].signals[0]  # the controller's signals all show its state
        return xosc.ValueTrigger(name, 0, xosc.ConditionEdge.none,
                                 xosc.TrafficSignalCondition(run.signal_id(sid), run.lamp_state(sid, state)))
    if fn == "var" and len(args) == 1 and op != "!=":
        return xosc.ValueTrigger(name, 0, xosc.ConditionEdge.none, xosc.VariableCondition(args[0], value, rule))
    if fn == "road_end" and len(args) == 1 and op == "<=" and value == 0.0:  # (its duration: `for D`)
        return xosc.EntityTrigger(name, 0, xosc.ConditionEdge.none, xosc.EndOfRoadCondition(0.0), args[0])
    if fn == "road_edge" and len(args) == 1 and op == "<" and value == 0.0:
        return xosc.EntityTrigger(name, 0, xosc.ConditionEdge.none, xosc.OffroadCondition(0.0), args[0])
    if fn == "ttc" and len(args) == 2:
        cond = xosc.TimeToCollisionCondition(value, rule, alongroute=False, freespace=True, entity=args[1],
                                             coordinate_system=xosc.CoordinateSystem.road)
        return xosc.EntityTrigger(name, 0, xosc.ConditionEdge.none, cond, args[0])
    return None


def _dnf(node) -> list[list]:
    """The formula as a disjunction of conjunctions of its leaves."""
    if isinstance(node, E.Binary) and node.op == "and":
        return [a + b for a in _dnf(node.left) for b in _dnf(node.right)]
    if isinstance(node, E.Binary) and node.op == "or":
        return _dnf(node.left) + _dnf(node.right)
    return [[node]]


def _running(conj: list) -> tuple[list, list[str]]:
    """The conjunction without the pairs `started(K) > 0`, `not ended(K) > 0` (a step running),
    and the keys K of those pairs."""
    def state_of(leaf):
        if isinstance(leaf, E.Binary) and leaf.op == ">" and isinstance(leaf.right, E.Num) \
                and leaf.right.value == 0.0 and _signal(leaf.left) is not None:
            fn, args = _signal(leaf.left)
            return (fn, args[0]) if len(args) == 1 else None
        return None
    started = {state_of(x)[1] for x in conj if state_of(x) and state_of(x)[0] == "started"}
    not_ended = {state_of(x.arg)[1] for x in conj if isinstance(x, E.Unary) and x.op == "not" and state_of(x.arg)
                 and state_of(x.arg)[0] == "ended"}
    keys = sorted(started & not_ended)
    rest = [x for x in conj if not any(state_of(x) == ("started", k) or
                                       (isinstance(x, E.Unary) and state_of(x.arg) == ("ended", k)) for k in keys)]
    return rest, keys


def _condition_groups(run: _Run, formula, event: str) -> list[list] | None:
    groups = []
    for conj in _dnf(formula):
        conj, running = _running(conj)
        conds = [_compare(run, leaf, run.unique(f"{event}_cond")) for leaf in conj] + \
            [_state_condition(run, "running", key, ">", 0.0, run.unique(f"{event}_cond")) for key in running]
        if any(c is None for c in conds):
            return None
        groups.append(conds)
    return groups if len(groups) <= 8 else None


EXPORT_EDGES = {None: xosc.ConditionEdge.none, "rising": xosc.ConditionEdge.rising,
                "falling": xosc.ConditionEdge.falling, "changing": xosc.ConditionEdge.risingOrFalling}


def _start_trigger(run: _Run, step: TriggerPlan, event: str, armed_by: list[str] | None,
                   point: str = "start") -> xosc.Trigger:
    """`armed_by`: the events whose start arms this step (None: armed at time 0); `point`:
    "start" (an event's StartTrigger) or "stop" (the storyboard's StopTrigger)."""
    common = []
    after = run.num(step.after_s) if step.after_s is not None else 0.0
    if armed_by is None:
        if after > 0.0 or (step.at_s is None and step.condition is None):
            common.append(xosc.ValueTrigger(run.unique(f"{event}_start"), 0, xosc.ConditionEdge.none,
                                            xosc.SimulationTimeCondition(after, xosc.Rule.greaterOrEqual)))
    else:
        for ref in armed_by:
            common.append(xosc.ValueTrigger(run.unique(f"{event}_armed"), after, xosc.ConditionEdge.none,
                                            xosc.StoryboardElementStateCondition(
                                                xosc.StoryboardElementType.event, ref,
                                                xosc.StoryboardElementState.startTransition)))
    if step.at_s is not None:
        common.append(xosc.ValueTrigger(run.unique(f"{event}_at"), 0, xosc.ConditionEdge.none,
                                        xosc.SimulationTimeCondition(run.num(step.at_s), xosc.Rule.greaterOrEqual)))
    groups = [[]]
    if step.condition is not None:
        got = _condition_groups(run, step.condition, event)
        if got is None:
            param = f"addt_condition_{len(run.placeholders) + 1}"
            run.placeholders.append(param)
            # (a parameter's dimension writes `P * speed(ego)` with P in its unit)
            text = format_expr(step.condition, param_dims={p.name: dim_of_name(p.dimension) for p in run.plan.params})
            run.conditions[param] = {"event": event, "formula": step.condition.model_dump(mode="json"),
                                     "text": text}
            run.carried.append(f"trigger `{text}` ({event}): no OpenSCENARIO condition; a ParameterCondition on "
                               f"{param}, which nothing sets")
            got = [[xosc.ValueTrigger(run.unique(f"{event}_when"), 0, xosc.ConditionEdge.none,
                                      xosc.ParameterCondition(param, "true", xosc.Rule.equalTo))]]
        ends = [c for conds in got for c in conds if isinstance(getattr(c, "entitycondition", None),
                                                                     xosc.EndOfRoadCondition)]
        if step.hold_s is not None and len(ends) == 1 and sum(len(conds) for conds in got) == 1:
            ends[0].entitycondition.duration = float(run.num(step.hold_s))  # at the end for D: exactly
        elif step.hold_s is not None:
            # `when C for D`: OpenSCENARIO's condition delay fires D after C first holds; it
            # does not ask C to keep holding (exact in the side file).
            hold = run.num(step.hold_s)
            run.holds[event] = float(hold)
            for conds in got:
                for c in conds:
                    c.delay = float(hold)
            run.carried.append(f"`when ... for {hold:g} s` ({event}): a condition delay of {hold:g} s (it does not "
                               "require the condition to keep holding)")
        if step.delay_s is not None or step.edge is not None:
            # `when EDGE C delayed D`: OpenSCENARIO's conditionEdge and delay, exactly (the edge
            # of each condition: exact for one condition, listed for several).
            delay = float(run.num(step.delay_s)) if step.delay_s is not None else 0.0
            edge = EXPORT_EDGES[step.edge]
            for conds in got:
                for c in conds:
                    c.delay = delay if step.hold_s is None else c.delay
                    c.conditionedge = edge
            if step.edge is not None and sum(len(conds) for conds in got) > 1:
                run.carried.append(f"`when {step.edge} ...` ({event}): the edge of each of its conditions, not of "
                                   "the whole condition")
        groups = got
    trigger = xosc.Trigger(point)
    for conds in groups:
        group = xosc.ConditionGroup(point)
        for c in common + conds:
            group.add_condition(c)
        trigger.add_conditiongroup(group)
    return trigger


def _event(run: _Run, actor: str, clause: ClausePlan, step: TriggerPlan | None, armed_by: str | None):
    settings = _resolve(run, clause.settings)
    cls_settings = _with_defaults(clause.name, settings)
    # A named step's event carries its name (an importer names the step after it).
    name = run.unique(step.label if step is not None and step.label else f"{actor}_{clause.name}")
    run.event_names.append(name)
    keyword = BEHAVIORS.get(clause.name).keyword  # aliases (`follow`) export as their behaviour
    actions, standard = ACTIONS[keyword](run, actor, cls_settings)
    # `repeat N`: the event back in standby after each run, N runs at most
    repeat = step.repeat if step is not None and step.repeat else 1
    event = xosc.Event(name, xosc.Priority.parallel, maxexecution=repeat)
    for action in actions:
        event.add_action(run.unique(f"{name}_action"), action)
    event.add_trigger(_start_trigger(run, step or TriggerPlan(), name, armed_by))
    run.behaviors[name] = {"actor": actor, "clause": clause.model_copy(
        update={"settings": {k: _literal(v) for k, v in settings.items()}}).model_dump(mode="json")}
    if not standard:
        run.carried.append(f"{actor}: behavior {clause.name} has no OpenSCENARIO action: controller "
                           f"{CONTROLLER_PREFIX}{clause.name} with its settings as properties ({name})")
    return event


def _resolve(run: _Run, settings: dict) -> dict:
    """Constant settings as numbers; a live one (`speed 1.2 * speed(ego)`) stays an expression."""
    out = {}
    for key, value in settings.items():
        live = not isinstance(value, (str, list)) and E.signals_used(value)
        out[key] = value if live else resolve_settings({key: value}, run.params)[key]
    return out


def _with_defaults(keyword: str, settings: dict) -> dict:
    return {**{p.name: p.default for p in BEHAVIORS.get(keyword).params}, **settings}


def _literal(value):
    if not isinstance(value, (str, list, int, float)):  # a live expression, as it is
        return value
    if isinstance(value, str):
        return value
    if isinstance(value, list):
        return [E.Num(value=float(v)) for v in value]
    return E.Num(value=float(value))


def _steps(run: _Run, actor: str, steps, maneuver: xosc.Maneuver) -> None:
    for step in steps:
        if step.group is None:
            maneuver.add_event(_named(run, actor, step, _event(run, actor, step.clause, step, None)))
            continue
        first = len(run.event_names)
        _flatten(run, actor, step, maneuver, None)
        # The group's events, in OpenSCENARIO for other tools; exactly, in the side file.
        run.groups.setdefault(actor, []).append(step.model_dump(mode="json"))
        run.group_events.update(run.event_names[first:])
        run.carried.append(f"{actor}: a `{step.group.mode}` block: events linked by storyboard-element "
                           "conditions (the step semantics exactly in the side file)")


def _named(run: _Run, actor: str, step: TriggerPlan, event: xosc.Event) -> xosc.Event:
    """Remember the event of a named step (for the conditions that read its state)."""
    if step.label:
        run.label_events[f"{actor}.{step.label}"] = event.name
    return event


def _flatten(run: _Run, actor: str, step: TriggerPlan, maneuver: xosc.Maneuver, armed_by: list[str] | None):
    """Events for one step; returns the events whose start together mean the step is done."""
    if step.group is None:
        event = _named(run, actor, step, _event(run, actor, step.clause, step, armed_by))
        maneuver.add_event(event)
        return [event.name]
    if step.at_s is not None or step.after_s is not None or step.condition is not None:
        # An anchor event marks the moment the group step fires (a no-op action).
        name = run.unique(step.label or f"{actor}_{step.group.mode}")
        run.event_names.append(name)
        anchor = xosc.Event(name, xosc.Priority.parallel)
        anchor.add_action(run.unique(f"{name}_action"), xosc.VisibilityAction(True, True, True))
        anchor.add_trigger(_start_trigger(run, step, name, armed_by))
        maneuver.add_event(_named(run, actor, step, anchor))
        armed_by = [name]
    if step.group.mode == "parallel":
        done = []
        for sub in step.group.steps:
            done += _flatten(run, actor, sub, maneuver, armed_by)
        return done or (armed_by or [])
    for sub in step.group.steps:
        armed_by = _flatten(run, actor, sub, maneuver, armed_by)
    return armed_by or []


# ---------------------------------------------------------------- routes, environment

def _route_action(run: _Run, a: ActorPlan) -> xosc.AssignRouteAction:
    """The route as waypoints: one lane position in the middle of each road's stretch of it,
    the first at the actor's start (a connecting road gets one too, so a tool that plans
    between waypoints takes the same turn)."""
    road = run.plan.road(a.road)
    network = build_network([road])[a.road]
    lane = int(round(run.num(a.lane)))
    _, legs = resolve_route(network, list(a.route), lane, None)
    route = xosc.Route(run.unique(f"{a.name}_route"))
    route.add_waypoint(_position(run, a), xosc.RouteStrategy.shortest)
    seen = {legs[0].road_id} if legs else set()
    for leg in legs[1:]:
        if leg.road_id in seen:
            continue
        seen.add(leg.road_id)
        route.add_waypoint(xosc.LanePosition(0.5 * (leg.s_from + leg.s_to), 0.0, str(leg.lane), leg.road_id),
                           xosc.RouteStrategy.shortest)
    if len(route.waypoints) < 2:  # a one-road route: its end as the second waypoint
        leg = legs[-1]
        route.add_waypoint(xosc.LanePosition(leg.s_to, 0.0, str(leg.lane), leg.road_id),
                           xosc.RouteStrategy.shortest)
    run.carried.append(f"{a.name}: route {' -> '.join(a.route)} as an AssignRouteAction (waypoints mid-road)")
    return xosc.AssignRouteAction(route)


# lux of the sun overhead on a clear day, for the Sun's required intensity
SUN_LUX = 100000.0


def _environment(run: _Run, models: list[ClausePlan], name: str = "addt_environment"):
    """`environment { rain rate R  fog visibility V  light sun E }` as an EnvironmentAction (a
    change during the run: the models it gives; OpenSCENARIO keeps what it leaves out)."""
    if not models:
        return None
    got = {m.name: resolve_settings(m.settings, run.params) for m in models}
    precipitation = sun = fog = None
    if "rain" in got:  # OpenSCENARIO's intensity is in mm/h
        rate_mm_h = got["rain"]["rate"] / units.lookup("mm/h").factor
        precipitation = xosc.Precipitation(xosc.PrecipitationType.rain, rate_mm_h)
    if "fog" in got:
        fog = xosc.Fog(got["fog"]["visibility"])
    if "light" in got:
        elevation = Light(got["light"]).elevation()  # a time of day as the elevation it gives
        sun = xosc.Sun(SUN_LUX * max(0.0, math.sin(elevation)), 0.0, elevation)
    for other in sorted(got.keys() - {"rain", "fog", "light", "road"}):
        run.carried.append(f"environment model {other} (side file only)")
    road = xosc.RoadCondition(got["road"]["friction"]) if "road" in got else None
    weather = xosc.Weather(sun=sun, fog=fog, precipitation=precipitation) if got.keys() - {"road"} else None
    run.carried.append(f"environment as an EnvironmentAction ({name}; the sensor models' settings exactly in the "
                       "side file)")
    return xosc.EnvironmentAction(xosc.Environment(name, weather=weather, roadcondition=road))


def _environment_group(run: _Run) -> xosc.ManeuverGroup | None:
    """Changes of the conditions during the run: one event per step, its EnvironmentAction."""
    if not run.plan.environment_steps:
        return None
    maneuver = xosc.Maneuver(f"{ENVIRONMENT_GROUP}_maneuver")
    for step in run.plan.environment_steps:
        name = run.unique(f"environment_{step.clause.name}")
        event = xosc.Event(name, xosc.Priority.parallel)
        event.add_action(run.unique(f"{name}_action"), _environment(run, [step.clause], name))
        event.add_trigger(_start_trigger(run, step, name, None))
        maneuver.add_event(event)
    group = xosc.ManeuverGroup(ENVIRONMENT_GROUP)
    group.add_maneuver(maneuver)
    return group


def _variable_group(run: _Run) -> xosc.ManeuverGroup | None:
    """Steps that set scenario variables: one event per step, its VariableSetAction
    (OpenSCENARIO 1.2's variables; the declarations are the scenario's)."""
    if not run.plan.variable_steps:
        return None
    maneuver = xosc.Maneuver(f"{VARIABLE_GROUP}_maneuver")
    for step in run.plan.variable_steps:
        name = run.unique(f"set_{step.clause.name}")
        event = xosc.Event(name, xosc.Priority.parallel)
        event.add_action(run.unique(f"{name}_action"),
                         xosc.VariableSetAction(step.clause.name, run.num(step.clause.settings["value"])))
        event.add_trigger(_start_trigger(run, step, name, None))
        maneuver.add_event(event)
    group = xosc.ManeuverGroup(VARIABLE_GROUP)
    group.add_maneuver(maneuver)
    return group


# ---------------------------------------------------------------- traffic lights

def _program_phases(times: list[tuple[str, float]], offset: float) -> list[tuple[str, str, float]]:
    """(phase name, colour, duration [s]) from time 0 of a program whose first colour starts
    at `offset` [s]: the cycle rotated to where it stands at 0 s, the colour it stands in
    split into a first phase (`<colour>_at_start`, what is left of it) and its last one
    (the part before 0 s), so the repeating phases are the program exactly."""
    timed = [(k, d) for k, d in times if d > 0.0]
    cycle = sum(d for _, d in timed)
    if not timed:
        return []
    at = (-offset) % cycle  # where in the cycle 0 s falls
    start = 0.0
    for i, (colour, d) in enumerate(timed):
        if at < start + d - 1e-9:
            break
        start += d
    rest = timed[i + 1:] + timed[:i]
    elapsed = at - start
    if elapsed <= 1e-9:
        return [(k, k, d) for k, d in [timed[i], *rest]]
    return [(f"{colour}_at_start", colour, d - elapsed), *((k, k, dd) for k, dd in rest), (colour, colour, elapsed)]


def _signal_controllers(run: _Run) -> list[xosc.TrafficSignalController]:
    """Each controller's program as phases green, yellow, red (a phase of 0 s is left out;
    an offset rotates them, `_program_phases`), each with the lamp states of the
    controller's signals."""
    out = []
    for c in run.plan.controllers:
        ctl = xosc.TrafficSignalController(c.name)
        times = [("green", run.num(c.green_s)), ("yellow", run.num(c.yellow_s)), ("red", run.num(c.red_s))]
        for name, colour, duration in _program_phases(times, run.num(c.offset_s)):
            phase = xosc.Phase(name, duration)
            for sid in c.signals:
                phase.add_signal_state(run.signal_id(sid), run.lamp_state(sid, colour))
            ctl.add_phase(phase)
        if ctl.phases:
            out.append(ctl)
        else:
            run.carried.append(f"controller {c.name}: a program of 0 s (no phases; the side file has it)")
    return out


def _light_event(run: _Run, step: TriggerPlan) -> xosc.Event:
    """A light step: `light C state S` sets each of C's signals (TrafficSignalStateAction);
    `state program` hands C back to its phases (a TrafficSignalControllerAction to its
    first phase; addt-dsl resumes the program's own cycle: exact in the side file)."""
    c = run.controllers[step.clause.name]
    state = step.clause.settings["state"]
    name = run.unique(f"light_{c.name}_{state}")
    event = xosc.Event(name, xosc.Priority.parallel)
    if state == LIGHT_PROGRAM:
        first = next((k for k, t in (("green", c.green_s), ("yellow", c.yellow_s), ("red", c.red_s))
                      if run.num(t) > 0.0), "green")
        event.add_action(run.unique(f"{name}_action"), xosc.TrafficSignalControllerAction(first, c.name))
        run.carried.append(f"light {c.name} state program ({name}): a TrafficSignalControllerAction to phase "
                           f"{first} (addt-dsl resumes the program's cycle)")
    else:
        for sid in c.signals:
            event.add_action(run.unique(f"{name}_action"),
                             xosc.TrafficSignalStateAction(run.signal_id(sid), run.lamp_state(sid, state)))
    event.add_trigger(_start_trigger(run, step, name, None))
    run.light_steps[name] = step.clause.model_dump(mode="json")
    return event


def _lights_group(run: _Run) -> xosc.ManeuverGroup | None:
    if not run.plan.light_steps:
        return None
    maneuver = xosc.Maneuver(f"{LIGHTS_GROUP}_maneuver")
    for step in run.plan.light_steps:
        maneuver.add_event(_light_event(run, step))
    group = xosc.ManeuverGroup(LIGHTS_GROUP)
    group.add_maneuver(maneuver)
    return group


def _lamps(plan, roads) -> dict[str, tuple[str, ...]]:
    """The lamp colours of each signal of the run's map (a generated file: type 1000001)."""
    if roads.generated:
        return {}
    network = build_network([plan.roads[0]])[plan.roads[0].name]
    return {sig.id: lamps_of(sig.type, sig.subtype) for road in network.roads.values() for sig in road.signals}


# ---------------------------------------------------------------- side file

def _sidecar(run: _Run, pinned: RunSpec) -> dict:
    plan = pinned.plan
    ego = plan.ego
    carried = run.carried
    if ego.stack is not None:
        carried.append(f"ego: stack {ego.stack.name} (the system under test; OpenSCENARIO has no stack)")
    for sensor in ego.sensors:
        carried.append(f"ego: sensor {sensor.name}")
    for f in pinned.faults:
        carried.append(f"fault {f.kind} {f.target} (fault schedules have no OpenSCENARIO equivalent)")
    for o in plan.oracles:
        carried.append(f"oracle {o.name} ({o.severity})")
    for a in plan.actors():
        for key in ("goal_s", "mu"):
            if getattr(a, key) is not None:
                carried.append(f"{a.name}: {key.removesuffix('_s')}")
        if a.ignore_lights:
            carried.append(f"{a.name}: at_red run (runs red lights; OpenSCENARIO has no such setting)")
    carried.append(f"run: step {plan.step_s} s, seed {pinned.seed}")
    return {
        "format": SIDECAR_FORMAT,
        "scenario": plan.name,
        "description": plan.description,
        "source_file": plan.source_file,
        "run_id": pinned.run_id,
        "step_s": plan.step_s,
        "seed": plan.seed,
        "run_seed": pinned.seed,
        "params": pinned.params,
        "param_dims": {p.name: p.dimension for p in plan.params},
        "actors": {a.name: {"vehicle": a.vehicle, "road": a.road, "length_m": a.length_m, "width_m": a.width_m,
                            "height_m": a.height_m,
                            "mass_kg": a.mass_kg, "wheelbase_m": a.wheelbase_m, "route": list(a.route),
                            "yaw": None if a.yaw is None else run.num(a.yaw),
                            "goal_s": None if a.goal_s is None else run.num(a.goal_s),
                            "mu": None if a.mu is None else run.num(a.mu),
                            "stack": None if a.stack is None else a.stack.model_dump(mode="json"),
                            "sensors": [s.model_dump(mode="json") for s in a.sensors],
                            "ignore_lights": a.ignore_lights, "reverse": a.reverse,
                            "stop_at_road_end": a.stop_at_road_end}
                   for a in plan.actors()},
        "faults": [f.model_dump(mode="json") for f in pinned.faults],
        "oracles": [o.model_dump(mode="json") for o in plan.oracles],
        "behaviors": run.behaviors,
        "conditions": run.conditions,
        "holds": run.holds,
        "groups": run.groups,
        "group_events": sorted(run.group_events),
        # Traffic lights: the controllers' programs, inline signals by name, and each light
        # step's clause by event name (`state program` has no exact OpenSCENARIO form).
        "lights": {"signals": [sig.model_dump(mode="json") for sig in plan.signals],
                   "signal_ids": run.signal_ids,
                   "controllers": {c.name: {k: run.num(getattr(c, k))
                                            for k in ("green_s", "yellow_s", "red_s", "offset_s")}
                                   for c in plan.controllers},
                   "steps": run.light_steps},
    }


# ---------------------------------------------------------------- entry point

def export_run(spec: RunSpec, out_dir: str | Path, stem: str | None = None) -> Export:
    """Write `<stem>.xosc`, its OpenDRIVE file and `<stem>.addt.json` into `out_dir`."""
    pinned = pin_spec(spec)
    plan = pinned.plan
    stem = stem or plan.name
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    roads = road_file(plan, stem)
    run = _Run(pinned, roads.road_ids)
    run.signal_ids = dict(roads.signal_ids)
    run.signal_lamps = _lamps(plan, roads)

    params = xosc.ParameterDeclarations()
    for p in plan.params:  # the run's values, for reference: the file uses the numbers
        params.add_parameter(xosc.Parameter(p.name, xosc.ParameterType.double, repr(float(pinned.params[p.name]))))
    params.add_parameter(xosc.Parameter(SIDECAR_PARAM, xosc.ParameterType.string, f"{stem}.addt.json"))

    entities = xosc.Entities()
    init = xosc.Init()
    for a in plan.actors():
        entities.add_scenario_object(a.name, _entity(a))
        init.add_init_action(a.name, xosc.TeleportAction(_position(run, a)))
        init.add_init_action(a.name, xosc.AbsoluteSpeedAction(run.num(a.speed), xosc.TransitionDynamics(
            xosc.DynamicsShapes.step, xosc.DynamicsDimension.time, 0)))
        if a.route:
            init.add_init_action(a.name, _route_action(run, a))
    environment = _environment(run, plan.environment)
    if environment is not None:
        init.add_global_action(environment)

    act = xosc.Act("addt_act", xosc.ValueTrigger("addt_act_start", 0, xosc.ConditionEdge.none,
                                                 xosc.SimulationTimeCondition(0, xosc.Rule.greaterOrEqual)))
    for a in plan.actors():
        maneuver = xosc.Maneuver(f"{a.name}_maneuver")
        for clause in a.behaviors:
            maneuver.add_event(_event(run, a.name, clause, None, None))
        _steps(run, a.name, a.triggers, maneuver)
        if maneuver.events:
            group = xosc.ManeuverGroup(f"{a.name}_maneuver_group")
            group.add_actor(a.name)
            group.add_maneuver(maneuver)
            act.add_maneuver_group(group)
    for group in (_lights_group(run), _environment_group(run), _variable_group(run)):
        if group is not None:
            act.add_maneuver_group(group)
    # The stop trigger before the references and parameters: its conditions may add some.
    duration = xosc.ValueTrigger("addt_duration", 0, xosc.ConditionEdge.rising,
                                 xosc.SimulationTimeCondition(plan.duration_s, xosc.Rule.greaterThan), "stop")
    if plan.end is None:
        stop = duration
    else:  # `end when ...`: its condition groups, or the duration
        stop = _start_trigger(run, plan.end, "addt_end", None, "stop")
        group = xosc.ConditionGroup("stop")
        group.add_condition(duration)
        stop.add_conditiongroup(group)
    for cond, key in run.state_refs:  # every named step is exported by now
        cond.reference = run.label_events[key]
    for param in run.placeholders:
        params.add_parameter(xosc.Parameter(param, xosc.ParameterType.boolean, "false"))
    if not act.maneuvergroup:  # an act needs a maneuver group: an empty one for the ego
        group = xosc.ManeuverGroup("ego_maneuver_group")
        group.add_actor(plan.ego.name)
        act.add_maneuver_group(group)
    story = xosc.Story("addt_story")
    story.add_act(act)
    storyboard = xosc.StoryBoard(init, stop)
    storyboard.add_story(story)

    network = xosc.RoadNetwork(roadfile=roads.name)
    for ctl in _signal_controllers(run):
        network.add_traffic_signal_controller(ctl)
    sidecar = _sidecar(run, pinned)
    variables = None
    if plan.variables:
        variables = xosc.VariableDeclarations()
        for v in plan.variables:
            variables.add_variable(xosc.Variable(v.name, xosc.ParameterType.double, repr(float(v.value))))
    scenario = xosc.Scenario(plan.name, "addt-dsl", params, entities, storyboard,
                             network, xosc.Catalog(), osc_minor_version=OSC_MINOR,
                             creation_date=creation_date(), variable_declaration=variables)
    xosc_path = out / f"{stem}.xosc"
    xodr_path = out / roads.name
    sidecar_path = out / f"{stem}.addt.json"
    # Atomic, and a failed write (a full disk) names the file.
    write_text(xosc_path, xml_text(scenario.get_element()))
    write_text(xodr_path, roads.text)
    write_text(sidecar_path, json.dumps(sidecar, indent=2) + "\n")
    return Export(xosc_path, xodr_path, sidecar_path, run.carried)

