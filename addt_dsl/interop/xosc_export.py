"""One run (a `RunSpec`) as OpenSCENARIO XML 1.2 + OpenDRIVE + a side file.

Written with the `scenariogeneration` package (no hand-built XML). The mapping, in
short (docs/openscenario.md has the full table):

- actors -> `ScenarioObject`s (a `Vehicle`, or a `Pedestrian` for `pedestrian`), the
  bounding box centred on the entity's reference point (addt-dsl places an actor's
  centre); the initial lane position (`TeleportAction` to a `LanePosition`) and speed
  (`AbsoluteSpeedAction`, step) go into `Init`;
- behaviours -> one `Event` each in the actor's `Maneuver`: `cruise` and `brake` are
  `AbsoluteSpeedAction`s with linear dynamics at their acceleration, `lane_change` and
  `cut_in` `AbsoluteLaneChangeAction`s over their duration; `idm`, `overtake`, `walk`
  and `cross` have no OpenSCENARIO action: they are `AssignControllerAction`s of a
  controller named `addt_<keyword>` whose properties are the settings;
- step start conditions -> the event's start trigger: `at T` / `after T` a
  `SimulationTimeCondition`, `s(A) > x` a `TraveledDistanceCondition`, `speed(A)`
  a `SpeedCondition`, `gap(A, B)` and `distance(A, B)` `RelativeDistanceCondition`s,
  `ttc(A, B)` a `TimeToCollisionCondition`; `and` within a condition group, `or`
  across groups; a formula with no such form becomes a `ParameterCondition` on a
  declared, never-set parameter `addt_condition_N`;
- the duration -> the storyboard's stop trigger;
- what OpenSCENARIO cannot say (the ego's stack and sensors, goal, tyre friction,
  the fault schedule, oracles, step, seeds, script groups, exact behaviour settings
  and trigger formulas) -> the side file `<stem>.addt.json` (named by the declared
  parameter `addt_sidecar`), listed in `Export.carried`. `xosc_import` reads it back.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

from scenariogeneration import xosc

from addt_dsl import expr as E
from addt_dsl.expr import eval_param_expr
from addt_dsl.interop.xodr_export import ExportError, road_file, xml_text
from addt_dsl.plan import ActorPlan, ClausePlan, RunSpec, TriggerPlan, resolve_settings
from addt_dsl.printer import format_expr, pin_spec
from addt_dsl.registry import BEHAVIORS
from addt_dsl.runtime.roadspec import build_network
from addt_dsl.vehicles import VEHICLES

OSC_MINOR = 2  # OpenSCENARIO 1.2
SIDECAR_FORMAT = "addt-xosc-sidecar/1"
SIDECAR_PARAM = "addt_sidecar"
CONTROLLER_PREFIX = "addt_"
RULES = {"<": xosc.Rule.lessThan, "<=": xosc.Rule.lessOrEqual, ">": xosc.Rule.greaterThan,
         ">=": xosc.Rule.greaterOrEqual, "==": xosc.Rule.equalTo, "!=": xosc.Rule.notEqualTo}
FLIP = {"<": ">", "<=": ">=", ">": "<", ">=": "<=", "==": "==", "!=": "!="}
CATEGORY = {"car": xosc.VehicleCategory.car, "truck": xosc.VehicleCategory.truck,
            "cyclist": xosc.VehicleCategory.bicycle}
__all__ = ["Export", "ExportError", "export_run", "SIDECAR_FORMAT", "SIDECAR_PARAM", "CONTROLLER_PREFIX"]


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
        self.groups: dict[str, list] = {}
        self.group_events: set[str] = set()  # events that belong to a group (the side file has its steps)
        self.event_names: list[str] = []
        self.placeholders: list[str] = []
        self.s0 = {a.name: self.num(a.s) for a in self.plan.actors()}
        self.v0 = {a.name: self.num(a.speed) for a in self.plan.actors()}
        self.names: set[str] = set()
        self.along = {a.name for a in self.plan.actors() if _along_s(self.plan, a, int(round(self.num(a.lane))))}

    def num(self, e) -> float:
        return float(eval_param_expr(e, self.params))

    def unique(self, base: str) -> str:
        name, i = base, 2
        while name in self.names:
            name, i = f"{base}_{i}", i + 1
        self.names.add(name)
        return name


# ---------------------------------------------------------------- entities

def _entity(a: ActorPlan):
    kind = VEHICLES[a.vehicle]
    box = xosc.BoundingBox(a.width_m, a.length_m, kind.height_m, 0.0, 0.0, kind.height_m / 2)
    if a.vehicle == "pedestrian":
        return xosc.Pedestrian(a.name, 80.0, xosc.PedestrianCategory.pedestrian, box, model=a.vehicle)
    if a.vehicle == "obstacle":
        return xosc.MiscObject(a.name, a.mass_kg, xosc.MiscObjectCategory.obstacle, box)
    front = xosc.Axle(0.5, 0.7, a.width_m * 0.85, a.wheelbase_m / 2, 0.35)
    rear = xosc.Axle(0.0, 0.7, a.width_m * 0.85, -a.wheelbase_m / 2, 0.35)
    return xosc.Vehicle(a.name, CATEGORY[a.vehicle], box, front, rear, 70.0, 10.0, 12.0, mass=a.mass_kg)


def _position(run: _Run, a: ActorPlan) -> xosc.LanePosition:
    offset = run.num(a.offset) if a.offset is not None else 0.0
    lane = int(round(run.num(a.lane)))
    road_id = a.route[0] if a.route else run.road_ids[a.road]
    if a.yaw is not None:  # both languages face an entity along its lane's driving direction
        orientation = xosc.Orientation(h=run.num(a.yaw), reference=xosc.ReferenceContext.relative)
        return xosc.LanePosition(run.num(a.s), offset, str(lane), road_id, orientation)
    return xosc.LanePosition(run.num(a.s), offset, str(lane), road_id)


def _along_s(plan, a: ActorPlan, lane: int) -> bool:
    """Whether the actor moves towards +s (no route, a lane driven along s)."""
    if a.route:
        return False
    road = plan.road(a.road)
    if road.source != "xodr":
        return lane < 0
    network = build_network([road])[a.road]
    return network.road(road.xodr_road_id or next(iter(network.roads))).travel_direction(lane) > 0


# ---------------------------------------------------------------- behaviours

def _speed_action(target: float, rate: float):
    return xosc.AbsoluteSpeedAction(target, xosc.TransitionDynamics(
        xosc.DynamicsShapes.linear, xosc.DynamicsDimension.rate, max(rate, 1e-3)))


def _cruise(run, actor, s):
    rate = s["accel"] if s["speed"] >= run.v0[actor] else s["decel"]
    return _speed_action(s["speed"], rate), True


def _brake(run, actor, s):
    return _speed_action(s["to_speed"], s["decel"]), True


def _lane_change(run, actor, s):
    return xosc.AbsoluteLaneChangeAction(int(round(s["to"])), xosc.TransitionDynamics(
        xosc.DynamicsShapes.cubic, xosc.DynamicsDimension.time, s["duration"])), True


def _controller(keyword: str):
    def make(run, actor, s):
        props = xosc.Properties()
        for key, value in s.items():
            props.add_property(key, json.dumps(value) if not isinstance(value, str) else value)
        ctrl = xosc.Controller(f"{CONTROLLER_PREFIX}{keyword}", props)
        return xosc.AssignControllerAction(ctrl, activateLateral=True, activateLongitudinal=True), False
    return make


# keyword -> (run, actor, resolved settings) -> (OpenSCENARIO action, whether it is a standard action)
ACTIONS = {"cruise": _cruise, "brake": _brake, "lane_change": _lane_change, "cut_in": _lane_change,
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


def _compare(run: _Run, node, name: str):
    """One comparison `signal op constant` as an OpenSCENARIO condition, or None."""
    if not isinstance(node, E.Binary) or node.op not in RULES:
        return None
    op, sig, value = node.op, _signal(node.left), _const(run, node.right)
    if sig is None:
        op, sig, value = FLIP[node.op], _signal(node.right), _const(run, node.left)
    if sig is None or value is None:
        return None
    fn, args = sig
    rule = RULES[op]
    if fn == "s" and op in (">", ">=") and len(args) == 1 and args[0] in run.along:
        cond = xosc.TraveledDistanceCondition(max(0.0, value - run.s0[args[0]]))
        return xosc.EntityTrigger(name, 0, xosc.ConditionEdge.none, cond, args[0])
    if fn == "speed" and len(args) == 1:
        return xosc.EntityTrigger(name, 0, xosc.ConditionEdge.none, xosc.SpeedCondition(value, rule), args[0])
    if fn in ("gap", "distance") and len(args) == 2:
        kind = xosc.RelativeDistanceType.longitudinal if fn == "gap" else xosc.RelativeDistanceType.euclidianDistance
        cond = xosc.RelativeDistanceCondition(value, rule, kind, args[1], alongroute=False, freespace=fn == "gap",
                                              coordinate_system=xosc.CoordinateSystem.road if fn == "gap"
                                              else xosc.CoordinateSystem.entity)
        return xosc.EntityTrigger(name, 0, xosc.ConditionEdge.none, cond, args[0])
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


def _condition_groups(run: _Run, formula, event: str) -> list[list] | None:
    groups = []
    for conj in _dnf(formula):
        conds = [_compare(run, leaf, run.unique(f"{event}_cond")) for leaf in conj]
        if any(c is None for c in conds):
            return None
        groups.append(conds)
    return groups if len(groups) <= 8 else None


def _start_trigger(run: _Run, step: TriggerPlan, event: str, armed_by: list[str] | None) -> xosc.Trigger:
    """`armed_by`: the events whose start arms this step (None: armed at time 0)."""
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
            text = format_expr(step.condition)
            run.conditions[param] = {"event": event, "formula": step.condition.model_dump(mode="json"),
                                     "text": text}
            run.carried.append(f"trigger `{text}` ({event}): no OpenSCENARIO condition; a ParameterCondition on "
                               f"{param}, which nothing sets")
            got = [[xosc.ValueTrigger(run.unique(f"{event}_when"), 0, xosc.ConditionEdge.none,
                                      xosc.ParameterCondition(param, "true", xosc.Rule.equalTo))]]
        groups = got
    trigger = xosc.Trigger()
    for conds in groups:
        group = xosc.ConditionGroup()
        for c in common + conds:
            group.add_condition(c)
        trigger.add_conditiongroup(group)
    return trigger


def _event(run: _Run, actor: str, clause: ClausePlan, step: TriggerPlan | None, armed_by: str | None):
    settings = resolve_settings(clause.settings, run.params)
    cls_settings = _with_defaults(clause.name, settings)
    name = run.unique(f"{actor}_{clause.name}")
    run.event_names.append(name)
    keyword = BEHAVIORS.get(clause.name).keyword  # aliases (`follow`) export as their behaviour
    action, standard = ACTIONS[keyword](run, actor, cls_settings)
    event = xosc.Event(name, xosc.Priority.parallel)
    event.add_action(run.unique(f"{name}_action"), action)
    event.add_trigger(_start_trigger(run, step or TriggerPlan(), name, armed_by))
    run.behaviors[name] = {"actor": actor, "clause": clause.model_copy(
        update={"settings": {k: _literal(v) for k, v in settings.items()}}).model_dump(mode="json")}
    if not standard:
        run.carried.append(f"{actor}: behavior {clause.name} has no OpenSCENARIO action: controller "
                           f"{CONTROLLER_PREFIX}{clause.name} with its settings as properties ({name})")
    return event


def _with_defaults(keyword: str, settings: dict) -> dict:
    return {**{p.name: p.default for p in BEHAVIORS.get(keyword).params}, **settings}


def _literal(value):
    if isinstance(value, str):
        return value
    if isinstance(value, list):
        return [E.Num(value=float(v)) for v in value]
    return E.Num(value=float(value))


def _steps(run: _Run, actor: str, steps, maneuver: xosc.Maneuver) -> None:
    for step in steps:
        if step.group is None:
            maneuver.add_event(_event(run, actor, step.clause, step, None))
            continue
        first = len(run.event_names)
        _flatten(run, actor, step, maneuver, None)
        # The group's events, in OpenSCENARIO for other tools; exactly, in the side file.
        run.groups.setdefault(actor, []).append(step.model_dump(mode="json"))
        run.group_events.update(run.event_names[first:])
        run.carried.append(f"{actor}: a `{step.group.mode}` block: events linked by storyboard-element "
                           "conditions (the step semantics exactly in the side file)")


def _flatten(run: _Run, actor: str, step: TriggerPlan, maneuver: xosc.Maneuver, armed_by: list[str] | None):
    """Events for one step; returns the events whose start together mean the step is done."""
    if step.group is None:
        event = _event(run, actor, step.clause, step, armed_by)
        maneuver.add_event(event)
        return [event.name]
    if step.at_s is not None or step.after_s is not None or step.condition is not None:
        # An anchor event marks the moment the group step fires (a no-op action).
        name = run.unique(f"{actor}_{step.group.mode}")
        run.event_names.append(name)
        anchor = xosc.Event(name, xosc.Priority.parallel)
        anchor.add_action(run.unique(f"{name}_action"), xosc.VisibilityAction(True, True, True))
        anchor.add_trigger(_start_trigger(run, step, name, armed_by))
        maneuver.add_event(anchor)
        armed_by = [name]
    if step.group.mode == "parallel":
        done = []
        for sub in step.group.steps:
            done += _flatten(run, actor, sub, maneuver, armed_by)
        return done or (armed_by or [])
    for sub in step.group.steps:
        armed_by = _flatten(run, actor, sub, maneuver, armed_by)
    return armed_by or []


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
        if a.route:
            carried.append(f"{a.name}: route {' -> '.join(a.route)} (no RoutingAction written)")
        for key in ("goal_s", "mu"):
            if getattr(a, key) is not None:
                carried.append(f"{a.name}: {key.removesuffix('_s')}")
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
                            "mass_kg": a.mass_kg, "wheelbase_m": a.wheelbase_m, "route": list(a.route),
                            "yaw": None if a.yaw is None else run.num(a.yaw),
                            "goal_s": None if a.goal_s is None else run.num(a.goal_s),
                            "mu": None if a.mu is None else run.num(a.mu),
                            "stack": None if a.stack is None else a.stack.model_dump(mode="json"),
                            "sensors": [s.model_dump(mode="json") for s in a.sensors]}
                   for a in plan.actors()},
        "faults": [f.model_dump(mode="json") for f in pinned.faults],
        "oracles": [o.model_dump(mode="json") for o in plan.oracles],
        "behaviors": run.behaviors,
        "conditions": run.conditions,
        "groups": run.groups,
        "group_events": sorted(run.group_events),
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
    for param in run.placeholders:
        params.add_parameter(xosc.Parameter(param, xosc.ParameterType.boolean, "false"))
    if not act.maneuvergroup:  # an act needs a maneuver group: an empty one for the ego
        group = xosc.ManeuverGroup("ego_maneuver_group")
        group.add_actor(plan.ego.name)
        act.add_maneuver_group(group)
    story = xosc.Story("addt_story")
    story.add_act(act)
    stop = xosc.ValueTrigger("addt_duration", 0, xosc.ConditionEdge.rising,
                             xosc.SimulationTimeCondition(plan.duration_s, xosc.Rule.greaterThan), "stop")
    storyboard = xosc.StoryBoard(init, stop)
    storyboard.add_story(story)

    sidecar = _sidecar(run, pinned)
    scenario = xosc.Scenario(plan.name, "addt-dsl", params, entities, storyboard,
                             xosc.RoadNetwork(roadfile=roads.name), xosc.Catalog(), osc_minor_version=OSC_MINOR)
    xosc_path = out / f"{stem}.xosc"
    xodr_path = out / roads.name
    sidecar_path = out / f"{stem}.addt.json"
    xosc_path.write_text(xml_text(scenario.get_element()))
    xodr_path.write_text(roads.text)
    sidecar_path.write_text(json.dumps(sidecar, indent=2) + "\n")
    return Export(xosc_path, xodr_path, sidecar_path, run.carried)

