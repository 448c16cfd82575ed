"""The storyboard: Init, stories, acts, maneuver groups, maneuvers and events, their start
triggers, sequences of events, and the stop trigger."""

import re
from dataclasses import dataclass
from xml.etree.ElementTree import Element  # an empty <Init> only: files are parsed with defusedxml

from addt_dsl import expr as E
from addt_dsl import units
from addt_dsl.expr import eval_param_expr
from addt_dsl.interop.openscenario.conditions import EDGES
from addt_dsl.interop.openscenario.entities import safe_name
from addt_dsl.interop.openscenario.params import all_of, any_of, is_number, plus_expr
from addt_dsl.interop.openscenario.positions import Placement
from addt_dsl.interop.openscenario.registry import GLOBAL_ACTIONS, INIT_ACTIONS, INIT_GLOBAL_ACTIONS, STORYBOARD
from addt_dsl.interop.openscenario.xml import Stop, child_at, first_of, only_child
from addt_dsl.plan import ClausePlan, GroupPlan, TriggerPlan

DEFAULT_DURATION_S = 60.0
ENDED_DURATION_S = 300.0  # the bound on a run that a stop condition ends (`end when`)
MAX_DURATION_S = 3600.0


# StoryboardElementStateCondition states on another actor's event, as step states
# (runningState: started and not ended, `step_state`).
STATE_SIGNAL = {"startTransition": "started", "runningState": "started",
                "endTransition": "ended", "completeState": "ended"}
# Actions that happen in one step: an event of only these that translates to no step
# (a teleport that only raises the actor) still starts, and ends at once (`instant_state`).
INSTANT_ACTIONS = frozenset({"TeleportAction"})


def step_state(state: str, step: str):
    """A storyboard element state as a formula on a named step's signals (a signal above 0,
    as the compiler lowers a state): running is started and not yet ended."""
    def on(signal: str):
        return E.Binary(op=">", left=E.Signal(name=f"{signal}({step})"), right=E.Num(value=0.0))
    if state == "runningState":
        return E.Binary(op="and", left=on("started"), right=E.Unary(op="not", arg=on("ended")))
    return on(STATE_SIGNAL[state])


def steps_of(step: TriggerPlan):
    """A step and every step of its groups, depth first."""
    yield step
    for sub in step.group.steps if step.group is not None else ():
        yield from steps_of(sub)


def labelled(step: TriggerPlan, clause: ClausePlan, label: str, found: list, same=None) -> TriggerPlan:
    """The step tree with the first step that starts `clause` named (its name if it has
    one, else `label`); the name used is appended to `found`. `same(a, b)`: how a step's
    clause is matched (default: equal)."""
    if not found and step.clause is not None and (same or ClausePlan.__eq__)(step.clause, clause):
        found.append(step.label or label)
        return step if step.label else step.model_copy(update={"label": label})
    if step.group is None:
        return step
    steps = [labelled(s, clause, label, found, same) for s in step.group.steps]
    return step.model_copy(update={"group": step.group.model_copy(update={"steps": steps})})


def speed_into_trajectory(clauses: list[ClausePlan]) -> list[ClausePlan]:
    """A speed action and an untimed trajectory in one event: OpenSCENARIO moves the entity
    along the trajectory at the speed the speed action sets; the language's trajectory holds
    the longitudinal channel itself, so it takes that speed (and its rate limits)."""
    cruise = next((c for c in clauses if c.name == "cruise" and c.settings.get("speed") is not None
                   and not any(isinstance(n, E.Signal) for n in E.walk(c.settings["speed"]))), None)
    traj = next((c for c in clauses if c.name == "trajectory" and "times" not in c.settings
                 and "speed" not in c.settings), None)
    if cruise is None or traj is None:
        return clauses
    extra = {k: cruise.settings[k] for k in ("accel", "decel") if k in cruise.settings}
    merged = traj.model_copy(update={"settings": {**traj.settings, "speed": cruise.settings["speed"], **extra}})
    return [merged if c is traj else c for c in clauses if c is not cruise]


def duration_of(clause: ClausePlan) -> float:
    """How long a behaviour runs [s], where its settings say: `duration`, or a timed
    trajectory's last vertex time; else 0."""
    d = clause.settings.get("duration")
    times = clause.settings.get("times")
    if not isinstance(d, E.Num) and isinstance(times, list) and times and isinstance(times[-1], E.Num):
        d = times[-1]
    return float(d.value) if isinstance(d, E.Num) else 0.0

# -- event priority (OpenSCENARIO 1.2 Event/@priority, esmini's Event::Start)
#
# override (1.0's overwrite): starting, the event ends every other running event of its
# maneuver (their actions stop where they are); skip: it does not start while another event
# of its maneuver runs (its start condition is asked again at the next step); parallel: it
# starts anyway. Whatever the priority, an event's start ends the running actions of the same
# actor on a control domain it shares (esmini's domain conflict; the twin's behaviour that
# replaces another on its channel). The domains of esmini's private actions
# (OSCPrivateAction.hpp); a wrapper element is looked through.
ACTION_DOMAINS = {"SpeedAction": {"long"}, "SpeedProfileAction": {"long"}, "LongitudinalDistanceAction": {"long"},
                  "SynchronizeAction": {"long"}, "AcquirePositionAction": {"long"}, "LaneChangeAction": {"lat"},
                  "LaneOffsetAction": {"lat"}, "LateralDistanceAction": {"lat"},
                  "FollowTrajectoryAction": {"lat", "long"}, "TeleportAction": {"lat", "long"},
                  "AssignRouteAction": set(), "VisibilityAction": set()}
# Actions that end in the step they start (a speed action of step dynamics too): nothing of
# them runs for another event to end.
AT_ONCE_ACTIONS = frozenset({"TeleportAction", "AssignRouteAction", "VisibilityAction", "EnvironmentAction",
                             "ParameterAction", "VariableAction", "TrafficSignalAction", "InfrastructureAction"})
ACTION_WRAPPERS = frozenset({"PrivateAction", "GlobalAction", "LongitudinalAction", "LateralAction",
                             "RoutingAction"})
ENDED_STATES = ("endTransition", "completeState")
END_MARGIN_S = 0.1  # an action's end against another's start on times: a few steps of esmini's either way


def action_leaf(action):
    """The element of the action an <Action> performs, through its wrappers (None: empty)."""
    el = only_child(action)
    while el is not None and el.tag in ACTION_WRAPPERS:
        inner = only_child(el)
        if inner is None:
            break
        el = inner
    return el


def at_once(leaf) -> bool:
    return leaf is not None and (leaf.tag in AT_ONCE_ACTIONS or (
        leaf.tag == "SpeedAction" and child_at(leaf, "SpeedActionDynamics") is not None
        and child_at(leaf, "SpeedActionDynamics").get("dynamicsShape") == "step"))


def event_domains(event, running: bool = True) -> set | None:
    """The control domains an event's actions take ({"long", "lat"}): of those that run on after
    their start (`running`; empty: they all end as they start), or of all (the domains whose
    running actions its start ends); None: an action whose domains are not known here."""
    out: set = set()
    for action in event.iterfind("Action"):
        leaf = action_leaf(action)
        if running and at_once(leaf):
            continue
        if leaf is None or leaf.tag not in ACTION_DOMAINS:
            return None
        out |= ACTION_DOMAINS[leaf.tag]
    return out


# The storyboard's structure (walked by `Storyboard`, not dispatched): each element under its
# parent, as the schema names it (docs/osc_schema.py).
for _path, _status, _note in (
        ("Storyboard/Init", "exact", "actions at the start: positions, speeds, routes, environment, lights"),
        ("Storyboard/Story", "exact", "stories run from the start"),
        ("Storyboard/StopTrigger", "approx", "a simulation time alone: the run's duration; other conditions "
                                             "end the run when they hold (`end when`, the run at most 300 s); "
                                             "without a simulation time, 60 s at most (W0802)"),
        ("Story/Act", "exact", "acts start with their story"),
        ("Story/ParameterDeclarations", "exact", "one scope with the global parameters (a global value wins)"),
        ("Act/ManeuverGroup", "approx", "one actor per group (more: refused); maximumExecutionCount above 1 refused"),
        ("Act/StartTrigger", "approx", "a simulation time, the story running, or another act complete (one "
                                       "condition: the act's steps a named group started on every event of that "
                                       "act ended, with its edge and delay); other conditions refused"),
        ("Act/StopTrigger", "refused", "the language has no act that ends; CARLA's criteria_* groups are oracles"),
        ("ManeuverGroup/Actors", "exact", "the actor the group's private actions drive"),
        ("ManeuverGroup/CatalogReference", "exact", "the Maneuver entry of the ManeuverCatalog's directory, its "
                                                    "parameters as the reference assigns them"),
        ("ManeuverGroup/Maneuver", "exact", "maneuvers run with their group"),
        ("Maneuver/Event", "approx", "each action a step; maximumExecutionCount as `when C repeat N` when a "
                                    "condition of its own starts it (without one, in an act started by another: "
                                    "`when started(A.ACT) repeat N`); complete after its last run. Priority: "
                                    "exact where no other event of the maneuver can be running when it starts "
                                    "(it starts on their end, they start on its state, their actions end as they "
                                    "start, it and they start on simulation times in file order, or their lane "
                                    "changes of a given time end 0.1 s before its time) and for "
                                    "parallel; an override whose actions take every domain of theirs replaces "
                                    "them (exact), else W0802 (their actions on other domains run on); skip as "
                                    "`when C and not (started(A.x) and not ended(A.x))` on a condition without "
                                    "edge or delay, else refused; a priority other than these refused"),
        ("Maneuver/ParameterDeclarations", "exact", "one scope with the global parameters (a global value wins)"),
        ("Event/Action", "exact", "private actions and traffic signal actions (see the actions)"),
        ("Event/StartTrigger", "approx", "condition groups as `any`/`all`, edges and delays; several edges or "
                                         "delays act on the whole condition (W0802)"),
        ("Init/Actions", "exact", "see the actions in Init"),
        ("InitActions/GlobalAction", "approx", "environment and traffic signals; others refused"),
        ("InitActions/Private", "exact", "see the actions in Init"),
        ("InitActions/UserDefinedAction", "refused", "a user-defined action means nothing to the twin"),
        ("Private/PrivateAction", "exact", "see the actions in Init"),
        ("Trigger/ConditionGroup", "exact", "groups are alternatives (`or`), conditions in a group `and`"),
        ("ConditionGroup/Condition", "exact", "see the conditions; delay and conditionEdge kept"),
):
    STORYBOARD.declare(_path, _status, _note)

# Global actions, by where they stand (Init, an event): the inner element each translation takes,
# found along its path under <GlobalAction>, in the order tried.
GLOBAL_PATHS = {"global action in Init": (("EnvironmentAction", ("EnvironmentAction", "Environment")),
                                          ("TrafficSignalAction", ("InfrastructureAction", "TrafficSignalAction"))),
                "global action": (("TrafficSignalAction", ("InfrastructureAction", "TrafficSignalAction")),
                                  ("EnvironmentAction", ("EnvironmentAction",)),
                                  ("ParameterAction", ("ParameterAction", "SetAction")),
                                  ("VariableAction", ("VariableAction", "SetAction")))}
# The traffic signal actions are translated by TrafficSignalAction's entry (documented here).
for _registry, _where in ((GLOBAL_ACTIONS, "a light step"), (INIT_GLOBAL_ACTIONS, "at time 0")):
    _registry.declare("TrafficSignalStateAction", "exact", f"`light C state S` ({_where}), C the signal's controller "
                      "(setting some of a controller's signals switches it all, W0802)")
    _registry.declare("TrafficSignalControllerAction", "approx", f"`light C state program` ({_where}): the program "
                      "resumes its own cycle, not the named phase (W0802)")
INIT_GLOBAL_ACTIONS.declare("ParameterAction", "refused", "a parameter's value at the start is its declaration's")
INIT_GLOBAL_ACTIONS.declare("VariableAction", "refused", "a variable's value at the start is its declaration's")
for _registry in (GLOBAL_ACTIONS, INIT_GLOBAL_ACTIONS):
    for _name, _note in (
            ("EntityAction", "the language's actors exist for the whole run (no adding or deleting)"),
            ("TrafficAction", "the twin has no traffic swarms, sources, sinks or areas"),
            ("SetMonitorAction", "monitors are the language's oracles, not set by actions"),
            ("UserDefinedAction", "a user-defined action means nothing to the twin"),
    ):
        _registry.declare(_name, "refused", _note)


@dataclass(frozen=True)
class AfterEvent:
    """A start on another event's state: that event, the delay [s], the state, the condition element."""
    ref: str
    delay: float
    state: str
    cond: object

    def fields(self) -> tuple:
        return self.ref, self.delay, self.state, self.cond


@dataclass(frozen=True)
class Start:
    """How a step starts: the fields of its TriggerPlan (at_s, condition, edge, delay_s, hold_s;
    none: at once), or, `after` another event, linked once every event is read."""
    fields: dict
    after: AfterEvent | None = None


@dataclass(frozen=True)
class EventStep:
    """A translated event: its actor and the clause of its (first) action."""
    actor: str
    clause: ClausePlan


@dataclass(frozen=True)
class InstantEvent:
    """An event whose actions happen at once and do nothing in the twin: its actor, its
    element and its act's start time [s] (its start read when a state of it is asked for)."""
    actor: str
    el: object
    act_at: float | None


@dataclass(frozen=True)
class PendingEvent:
    """An event started by another event: linked at the end (`link_sequences`)."""
    name: str
    actor: str
    after: AfterEvent
    clause: ClausePlan


@dataclass(frozen=True)
class Anchor:
    """An exported group's no-op event: the actor and the start of the group it starts."""
    actor: str
    fields: dict


@dataclass(frozen=True)
class InitLater:
    """Init actions translated once every actor is placed: (RoutingAction, actor) of a trajectory
    from the start, (LongitudinalAction, actor) of a speed relative to another entity's."""
    trajectories: list
    relative: list


# Init's wrappers: the inner actions tried, in this order.
INIT_WRAPPERS = {"RoutingAction": ("AssignRouteAction", "FollowTrajectoryAction"),
                 "LongitudinalAction": ("SpeedAction",)}


class Storyboard:
    # -- init

    def init(self, init) -> None:
        if init is None:  # no <Init>: every entity at its documented default place
            init = Element("Init")
        pairs = []
        for action in init.iterfind("Actions/GlobalAction"):
            if not self.global_action(INIT_GLOBAL_ACTIONS, action, "", pairs):
                self.skip(action, "global actions other than the environment (traffic, parameters, "
                                  "signals) are not translated")
        # a light's state in Init: a step at time 0
        self.light_steps += [TriggerPlan(clause=c) for c in self.light_event(pairs)]
        later = InitLater([], [])
        for private in init.iterfind("Actions/Private"):
            who = self.actor_name(private)
            if who is None or who not in self.actors:
                continue
            for pa in private.iterfind("PrivateAction"):
                act = only_child(pa)
                if act is not None:
                    self.init_action(act, who, later)
        init_trajectories, init_relative = later.trajectories, later.relative
        for act, who in init_relative:  # relative to another entity's initial speed
            rel = child_at(act, "SpeedAction", "SpeedActionTarget", "RelativeTargetSpeed")
            ref = self.actor_name(rel)
            if ref is None or ref not in self.actors:
                continue
            base = self.actors[ref].get("speed", E.Num(value=0.0))
            value = self.number(rel, "value", units.SPEED if rel.get("speedTargetValueType", "delta") == "delta"
                                else units.DIMENSIONLESS)
            op = "*" if rel.get("speedTargetValueType", "delta") == "factor" else "+"
            self.actors[who]["speed"] = E.Binary(op=op, left=value, right=base) if op == "*" else plus_expr(base, value)
            self.actors[who]["speed_now"] = eval_param_expr(self.actors[who]["speed"], self.param_values())
            if rel.get("continuous", "false") in ("true", "1") and (who != "ego" or self.scripted_ego):
                clause = self.relative_speed(child_at(act, "SpeedAction", "SpeedActionDynamics"), rel, self.actors[who])
                if clause is not None:
                    self.actors[who]["behaviors"].append(clause)
        for act, who in init_trajectories:  # no TeleportAction: start at the first vertex
            first_vertex = act.find("FollowTrajectoryAction//Polyline/Vertex/Position")
            if who not in self.placed and first_vertex is not None:
                got = self.position(first_vertex, who)
                if got is not None:
                    self.placed[who] = got
                    self.actors[who]["lane_now"] = got.lane
        for who, info in self.actors.items():
            if who not in self.placed:
                self.approx(info["el"], f"{who} has no translated initial position: lane -1 at s = 0 m of the "
                                        "first road")
                first = self.road(next(iter(self.network.roads)), info["el"])
                self.placed[who] = Placement(first, -1, E.Num(value=0.0), E.Num(value=0.0))
        for act, who in init_trajectories:  # a trajectory from the start: once every actor is placed
            clause = self.trajectory(child_at(act, "FollowTrajectoryAction"), who)
            if clause is not None:
                self.actors[who]["behaviors"].append(clause)

    # -- stop trigger

    def global_action(self, registry, action, event: str, lights: list) -> bool:
        """A GlobalAction through `registry` (Init's or an event's), its inner actions tried in the
        order of GLOBAL_PATHS; the light clauses it sets are added to `lights` as (element,
        clause) pairs. False: no translation takes it."""
        for name, path in GLOBAL_PATHS[registry.family]:
            translate = registry.translator(name)
            if child_at(action, *path) is not None and translate is not None:
                translate(self, action, event, lights)
                return True
        return False

    @INIT_GLOBAL_ACTIONS.register("EnvironmentAction", "approx", "fog, rain, the sun's elevation or a time of "
                                  "day (latitude 45 deg), the road's friction scale; clouds, wind, temperature, "
                                  "pressure and other precipitation have no model (W0802)")
    def init_environment(self, action, event: str, lights: list) -> None:
        self.environment_action(child_at(action, "EnvironmentAction", "Environment"))

    @INIT_GLOBAL_ACTIONS.register("TrafficSignalAction", "approx", "see TrafficSignalStateAction and "
                                  "TrafficSignalControllerAction")
    def init_lights(self, action, event: str, lights: list) -> None:
        lights += [(action, c) for c in self.light_clauses(action)]

    @GLOBAL_ACTIONS.register("TrafficSignalAction", "approx", "see TrafficSignalStateAction and "
                             "TrafficSignalControllerAction")
    def event_lights(self, body, event: str, lights: list) -> None:
        exact = ((self.sidecar or {}).get("lights") or {}).get("steps", {}).get(event)
        if exact and exact.get("name") not in self.light_ctls:
            self.error(body, f"the side file's light step {event!r} names controller "
                             f"{exact.get('name')!r}, which this file does not have")
            raise Stop
        lights += [(body, ClausePlan.model_validate(exact))] if exact else \
            [(body, c) for c in self.light_clauses(body)]

    @GLOBAL_ACTIONS.register("EnvironmentAction", "approx", "an environment step (`at T fog visibility V`): as in "
                             "Init")
    def event_environment(self, body, event: str, lights: list) -> None:
        env = child_at(body, "EnvironmentAction", "Environment")
        ref = child_at(body, "EnvironmentAction", "CatalogReference")
        if env is None and ref is not None:
            env = self.catalog_entry(ref, kinds=("Environment",))
        if env is None:
            if ref is None:
                self.skip(body.find("EnvironmentAction"), "an EnvironmentAction without an <Environment>")
            return
        lights += [(body, model) for model in self.environment_models(env)]

    @GLOBAL_ACTIONS.register("ParameterAction", "exact", "a SetAction to a number: a step of the `variables` "
                             "block (`set P V`), the parameter a scenario variable (its declaration's value at "
                             "the start) that ParameterConditions read as `var(P)`; ModifyAction refused")
    @GLOBAL_ACTIONS.register("VariableAction", "exact", "a SetAction to a number: as ParameterAction's (`set V X`); "
                             "ModifyAction refused")
    def event_set(self, body, event: str, lights: list) -> None:
        inner = only_child(body)
        ref = self.raw(inner, "parameterRef" if inner.tag == "ParameterAction" else "variableRef")
        name = self.variable(ref, inner)
        if name is None:
            return
        value = self.value(child_at(inner, "SetAction"), "value")
        lights.append((body, ClausePlan(keyword="set", name=name, settings={"value": E.Num(value=value)})))

    def variable(self, ref: str, el) -> str | None:
        """The scenario variable of a parameter (or a 1.2 variable) that actions set, declared
        with its first value at its first use; None after a diagnostic."""
        if ref in self.variables:
            return ref
        decl = self.doc.find(f"ParameterDeclarations/ParameterDeclaration[@name='{ref}']") \
            if re.fullmatch(r"[A-Za-z_]\w*", ref or "") else None
        if decl is None:
            decl = self.doc.find(f"VariableDeclarations/VariableDeclaration[@name='{ref}']") \
                if re.fullmatch(r"[A-Za-z_]\w*", ref or "") else None
        kind = (decl.get("parameterType") or decl.get("variableType") or "") if decl is not None else ""
        if decl is None or kind not in ("double", "integer", "unsignedInt", "unsignedShort", "int"):
            self.skip(el, f"'{ref}' is not a number declared at the scenario's top level: not translated",
                      "scenario variables are numbers (double, integer)")
            return None
        self.variables[ref] = self.value(decl, "value")
        return ref

    def init_action(self, act, who: str, later: "InitLater") -> None:
        """A private action of Init, dispatched through registry.INIT_ACTIONS (a wrapper's inner
        actions in the order of INIT_WRAPPERS); what no translation takes is refused."""
        for name in INIT_WRAPPERS.get(act.tag, (act.tag,)):
            inner = act if name == act.tag else act.find(name)
            translate = INIT_ACTIONS.translator(name)
            if inner is not None and translate is not None and translate(self, inner, who, act, later):
                return
        self.skip(act, f"<{act.tag}> in Init is not translated (positions and speeds are)")

    @INIT_ACTIONS.register("TeleportAction", "exact", "the actor's start position (see the position types)")
    def init_teleport(self, act, who: str, wrapper, later) -> bool:
        got = self.position(act.find("Position"), who)
        if got is not None:
            self.placed[who] = got
            self.actors[who]["lane_now"] = got.lane
            self.actors[who]["against_s"] = self.against_s(act.find("Position"), got)
            self.actors[who]["heading"] = self.file_heading(act.find("Position"), got)
        return True

    @INIT_ACTIONS.register("AssignRouteAction", "exact", "the actor's route (inline or from a route catalog)")
    def init_route(self, el, who: str, wrapper, later) -> bool:
        route_el = self.route_element(el)
        if route_el is not None:
            self.actors[who]["route_el"] = route_el
        return True

    @INIT_ACTIONS.register("FollowTrajectoryAction", "approx", "a trajectory from the start (as in an event); "
                           "the ego's only when it is scripted")
    def init_trajectory(self, el, who: str, wrapper, later) -> bool:
        if who != "ego" or self.scripted_ego:
            later.trajectories.append((wrapper, who))
            return True
        return False

    @INIT_ACTIONS.register("SpeedAction", "exact", "the start speed (absolute, or relative to another entity's "
                           "start speed); with dynamics, a speed change from standstill")
    def init_speed(self, speed, who: str, wrapper, later) -> bool:
        act = wrapper
        if child_at(speed, "SpeedActionTarget", "AbsoluteTargetSpeed") is not None:
            target = child_at(act, "SpeedAction", "SpeedActionTarget", "AbsoluteTargetSpeed")
            dyn = child_at(act, "SpeedAction", "SpeedActionDynamics")
            if dyn is not None and dyn.get("dynamicsShape", "step") != "step" \
                    and (who != "ego" or self.scripted_ego) \
                    and self.value(dyn, "value", default=0.0) > 0:
                # A speed change with dynamics in Init starts from standstill (OpenSCENARIO:
                # Init actions run as the simulation starts) and takes its time.
                clause = self.speed_action(dyn, target, self.actors[who])
                if clause is not None:
                    self.actors[who]["behaviors"].append(clause)
                return True
            self.actors[who]["speed"] = self.number(target, "value", units.SPEED)
            self.actors[who]["speed_now"] = self.value(target, "value")
            return True
        if child_at(speed, "SpeedActionTarget", "RelativeTargetSpeed") is not None:
            later.relative.append((act, who))
            return True
        return False

    @INIT_ACTIONS.register("ControllerAction", "approx", "the entity follows its actions, as under OpenSCENARIO's "
                           "default controller (W0802)")
    @INIT_ACTIONS.register("ActivateControllerAction", "approx", "as ControllerAction")
    def init_controller(self, act, who: str, wrapper, later) -> bool:
        self.approx(act, "a controller: the entity follows its actions, as under the default "
                         "controller of OpenSCENARIO (the driver models of esmini are not emulated)")
        return True

    def stop_trigger(self, trigger) -> float:
        """The run's duration: a stop condition group that is a simulation time alone (the
        rest of the stop trigger is `end when ...`, `end_trigger`); without one, a bound:
        longer where other stop conditions end the run."""
        for group in trigger.iterfind("ConditionGroup") if trigger is not None else ():
            conds = list(group.iterfind("Condition"))
            time = conds[0].find("ByValueCondition/SimulationTimeCondition") if len(conds) == 1 else None
            if time is not None and (time.get("rule") or "").startswith("greater"):
                end = units.decimal_sum((self.value(time, "value"), self.value(conds[0], "delay", units.TIME, 0.0)))
                return min(max(end, 0.1), MAX_DURATION_S)
        others = trigger is not None and any(True for _ in trigger.iterfind("ConditionGroup/Condition"))
        bound = ENDED_DURATION_S if others else DEFAULT_DURATION_S
        self.approx(trigger, f"no simulation-time stop trigger: at most {bound:g} s"
                    + (" (the run ends when its stop condition holds)" if others else ""))
        return bound

    # -- storyboard

    def story(self, story) -> None:
        self.story_name = story.get("name", "")
        acts = list(story.iterfind("Act"))
        self.act_travel = None  # (entity, distance [m]) of a CARLA act started on its travelled distance
        for act in acts:
            self.act_name = act.get("name", "")
            act_at = after_act = None
            groups = list(act.iterfind("StartTrigger/ConditionGroup"))
            conds = list(act.iterfind("StartTrigger/ConditionGroup/Condition"))
            runner_conds = []  # CARLA: conditions ScenarioRunner's reading translates (`runner_act_start`)
            for cond in conds:
                time = cond.find("ByValueCondition/SimulationTimeCondition")
                sesc = cond.find("ByValueCondition/StoryboardElementStateCondition")
                if len(groups) > 1:
                    self.skip(cond, "an act start trigger of several condition groups is not translated")
                elif time is not None and (time.get("rule") or "").startswith("greater") \
                        and self.value(cond, "delay", units.TIME, 0.0) == 0.0:
                    value = self.value(time, "value")
                    act_at = max(act_at or 0.0, value) if value > 0 else act_at
                elif sesc is not None and self.raw(sesc, "storyboardElementType") == "story" \
                        and self.raw(sesc, "storyboardElementRef") == self.story_name \
                        and self.raw(sesc, "state") in ("startTransition", "runningState") \
                        and self.value(cond, "delay", units.TIME, 0.0) == 0.0:
                    continue  # its own story running: the act starts with it
                elif sesc is not None and len(conds) == 1 and self.raw(sesc, "storyboardElementType") == "act" \
                        and self.raw(sesc, "state") in ("endTransition", "completeState") \
                        and self.raw(sesc, "storyboardElementRef") in self.act_events:
                    after_act = cond  # an earlier act complete: the act's steps form a group started then
                elif self.carla and len(groups) == 1:
                    runner_conds.append(cond)
                else:
                    self.skip(cond, "act start conditions other than the simulation time and the story running "
                                    "are not translated")
            runner_start = start = self.runner_act_start(runner_conds) if runner_conds else None
            if start is not None and start.get("at_s") is not None:
                act_at = max(act_at or 0.0, start.pop("at_s"))  # (ScenarioRunner: both once true)
            if start is not None and not start:
                runner_start = start = None  # (only conditions that hold from the first tick)
            # An act that starts once an entity has travelled a distance, which then stays true:
            # each of its events starts on that and its own condition at once (no group, so
            # events may follow each other); events counting time from the act's start need
            # the act as a group armed at its start.
            self.act_condition = None
            if start is not None and self.act_travel is not None and not any(
                    ev.find("StartTrigger//SimulationTimeCondition") is not None for ev in act.iter("Event")):
                self.act_condition, start = start["condition"], None
            stops = [g for g in act.iterfind("StopTrigger/ConditionGroup")
                     if not all((c.get("name") or "").startswith("criteria_") for c in g.iterfind("Condition"))]
            if stops and not (self.carla and len(acts) == 1):
                for stop in stops:  # (CARLA ScenarioRunner's pass criteria are oracles: pass_criteria)
                    self.skip(stop, "act stop triggers are not translated")
            before = self.act_begin(after_act if start is None else act)
            if start is not None and act_at is not None:
                start["at_s"] = E.Num(value=act_at)
            # (ScenarioRunner: an event's conditions are checked from its act's start on)
            self.events_travel = self.act_travel if runner_start is not None else None
            for group in act.iterfind("ManeuverGroup"):
                self.maneuver_group(group, act_at if start is None else None)
            self.events_travel = None
            self.act_end(act, after_act, before, start)
            self.act_condition = None
            if stops and self.carla and len(acts) == 1:
                self.runner_act_stop(stops, runner_start, act_at)
        self.link_sequences()
        self.skip_priority()

    def act_begin(self, after_act) -> dict:
        """Where each actor's steps stand before an act (`act_end` takes what the act added);
        an act started by another's completion names its group (`self.act_label`) first."""
        self.act_label = None
        self.act_first_event = len(self.event_order)
        if after_act is not None:
            taken = {tr.label for a in self.actors.values() for t in a["triggers"] for tr in steps_of(t) if tr.label}
            self.act_label = safe_name(self.act_name, taken)
        return {who: (len(info["triggers"]), len(info["behaviors"])) for who, info in self.actors.items()} | {
            "": (len(self.pending), len(self.light_steps) + len(self.variable_steps) + len(self.environment_steps))}

    def act_end(self, act, after_act, before: dict, start: dict | None = None) -> None:
        """Record the act's events (an act's completion is all of them complete); an act
        started by another act's completion (esmini: its events are armed from then), or on
        the conditions ScenarioRunner reads (`start`: a step's fields), becomes, per actor, a
        named parallel group of its steps: `ACT: when ended(...) delayed D then parallel { ... }`."""
        self.act_events[self.act_name] = self.event_order[self.act_first_event:]
        label, self.act_label = self.act_label, None
        added = [who for who, info in self.actors.items()
                 if (len(info["triggers"]), len(info["behaviors"])) != before.get(who, (0, 0))]
        if (after_act is None and start is None) or not added:
            return  # (nothing of it translates: its events said why)
        where = after_act if start is None else act.find("StartTrigger")
        if (len(self.pending), len(self.light_steps) + len(self.variable_steps) + len(self.environment_steps)) \
                != before[""]:
            self.skip(where, "an act started by another act's completion or an entity's condition whose events "
                             "start on other events, or set lights, variables or the environment, is not translated")
            return
        if start is not None:
            fields = start
        else:
            sesc = after_act.find("ByValueCondition/StoryboardElementStateCondition")
            ref = self.raw(sesc, "storyboardElementRef")
            parts = [self.event_state(e, "completeState") for e in self.act_events.get(ref, ())]
            if not parts or any(p is None for p in parts):
                self.skip(after_act, f"act '{self.act_name}' starts when act '{ref}' is complete, and not every "
                                     f"event of '{ref}' translates to a step")
                return
            fields = {"condition": all_of(parts)}
            edge = EDGES.get(after_act.get("conditionEdge", "none"))
            if edge:
                fields["edge"] = edge
            delay = self.value(after_act, "delay", units.TIME, 0.0)
            if delay > 0:
                fields["delay_s"] = E.Num(value=delay)
        for who, info in self.actors.items():
            t0, b0 = before.get(who, (0, 0))
            steps = [TriggerPlan(clause=c) for c in info["behaviors"][b0:]] + info["triggers"][t0:]
            if not steps:
                continue
            del info["behaviors"][b0:], info["triggers"][t0:]
            info["triggers"].append(TriggerPlan(label=label, group=GroupPlan(mode="parallel", steps=steps),
                                                **fields))

    def runner_act_start(self, conds: list) -> dict | None:
        """A CARLA act's start trigger as ScenarioRunner reads it (srunner/scenarios/
        open_scenario.py, `_create_condition_container`): its conditions start being checked
        with the story (time 0); each counts once it has held (a one-shot behaviour), with
        no edge; a `delay` D waits D before the condition is first checked; a
        SimulationTimeCondition measures from then. The fields of the act's step ({} when
        every condition holds from the first tick); None after a diagnostic."""
        at_s, formulas = None, []
        for cond in conds:
            delay = self.value(cond, "delay", units.TIME, 0.0)
            time = cond.find("ByValueCondition/SimulationTimeCondition")
            if time is not None:
                value, rule = self.value(time, "value"), time.get("rule") or ""
                if rule == "equalTo" and value == 0.0:
                    continue  # true at the first check, and it stays counted
                if rule.startswith("greater"):
                    at_s = max(at_s or 0.0, delay + value)
                    continue
                self.skip(cond, f"an act start condition on the simulation time ({rule}) is not translated")
                return None
            if delay > 0:
                at_s = max(at_s or 0.0, delay)  # (then the condition, each instant from D on)
            formulas.append((self.condition(cond, "ego"), cond))
            travel = cond.find("ByEntityCondition/EntityCondition/TraveledDistanceCondition")
            refs = list(cond.iterfind("ByEntityCondition/TriggeringEntities/EntityRef"))
            if travel is not None and len(refs) == 1:
                self.act_travel = (self.actor_name(refs[0]), self.value(travel, "value", units.LENGTH))
        if any(f is None for f, _ in formulas):
            return None
        if len(formulas) > 1:
            self.skip(formulas[1][1], "several entity conditions in an act start trigger (ScenarioRunner: each "
                                      "counts once it has held) are not translated")
            return None
        fields = {"condition": formulas[0][0]} if formulas else {}
        if at_s is not None:
            fields["at_s"] = at_s
        if formulas:
            self.approx(formulas[0][1], "an act start condition read as CARLA ScenarioRunner reads it: once it "
                                        "has held (no edge); the act's events are armed then, their simulation "
                                        "times counted from then")
        return fields

    def runner_act_stop(self, groups: list, start: dict | None, act_at: float | None) -> None:
        """A CARLA story's only act's stop trigger as ScenarioRunner reads it: its conditions
        are checked from the act's start, any one counts (`success_on_all=False`), and when
        one holds the act ends, and with it the story and the run: `end when ...`. A
        TraveledDistanceCondition counts from where the entity was when the act started; a
        SimulationTimeCondition from then, after the condition's delay."""
        alternatives, ends_at = [], []
        for cond in (c for g in groups for c in g.iterfind("Condition")):
            if (cond.get("name") or "").startswith("criteria_"):
                continue
            delay = self.value(cond, "delay", units.TIME, 0.0)
            time = cond.find("ByValueCondition/SimulationTimeCondition")
            travel = cond.find("ByEntityCondition/EntityCondition/TraveledDistanceCondition")
            if time is not None and (time.get("rule") or "").startswith("greater") and \
                    (start is None or "condition" not in start):
                ends_at.append((act_at or 0.0) + delay + self.value(time, "value"))
                continue
            refs = list(cond.iterfind("ByEntityCondition/TriggeringEntities/EntityRef"))
            who = self.actor_name(refs[0]) if len(refs) == 1 else None
            # Travelled since the act started: from the start threshold where the act starts on
            # that entity's travelled distance, from 0 where it starts with the story.
            since = 0.0 if start is None and act_at is None else \
                self.act_travel[1] if start is not None and self.act_travel and self.act_travel[0] == who else None
            if travel is not None and delay == 0.0 and who is not None and since is not None:
                d = self.value(travel, "value", units.LENGTH)
                alternatives.append(E.Binary(op=">=", left=E.Signal(name=f"s({who})"),
                                             right=plus_expr(self.start_station(who), E.Num(value=since + d))))
                if since:
                    self.approx(cond, "an act stop after a travelled distance: counted from the act's start "
                                      "threshold (ScenarioRunner: from where the entity was at the act's start, "
                                      "up to one tick past it)")
                continue
            self.skip(cond, "act stop conditions other than a time or a distance travelled since the act's start "
                            "are not translated")
            return
        if ends_at:
            self.act_stop_s = min(ends_at)  # the run's duration
        if alternatives:
            self.act_stop = any_of(alternatives)
        self.approx(groups[0], "the run ends at the act's stop, not when all of the act's events are complete "
                               "(ScenarioRunner ends the story then)")

    def maneuver_group(self, group, act_at) -> None:
        refs = [self.actor_name(r) for r in group.iterfind("Actors/EntityRef")]
        refs = [r for r in refs if r is not None]
        if int(self.value(group, "maximumExecutionCount", default=1.0)) > 1:
            self.skip(group, "a maneuver group that runs more than once is not translated")
        if len(refs) > 1:
            self.skip(group, f"maneuver group with {len(refs)} actors: translated for one actor only")
        who = refs[0] if refs else None  # no actor: its events' global actions (light steps) only
        for maneuver in group.iterfind("Maneuver"):
            self.maneuver(maneuver, who, act_at)
        for ref in group.iterfind("CatalogReference"):
            maneuver = self.catalog_entry(ref, ("Maneuver",))
            if maneuver is None:
                continue
            # The entry's parameters: its declarations as the reference assigns them, each
            # assignment read where the reference stands (`$MS1EgoS` may assign `$MS1EgoS`).
            # Local to this use: numbers, never plan parameters (a `${...}` literal).
            local = {d.get("name", ""): d.get("value", "")
                     for d in maneuver.iterfind("ParameterDeclarations/ParameterDeclaration")}
            try:
                local.update({a.get("parameterRef", "").removeprefix("$"): self.resolve(a.get("value", ""))
                              for a in ref.iterfind("ParameterAssignments/ParameterAssignment")})
            except (KeyError, SyntaxError, ValueError, ArithmeticError, RecursionError, MemoryError):
                self.error(ref, "a parameter assignment that does not evaluate")
                continue
            saved = dict(self.params)
            self.params.update({k: ("string", f"${{{v}}}" if is_number(v) else v) for k, v in local.items()})
            try:
                self.maneuver(maneuver, who, act_at)
            finally:
                self.params = saved

    def maneuver(self, maneuver, who: str, act_at) -> None:
        self.maneuvers.setdefault(maneuver.get("name", ""), []).extend(
            e.get("name", "") for e in maneuver.iterfind("Event"))
        events = list(maneuver.iterfind("Event"))
        # Where the act's start time is known: a time, else 0 s (an act started by another's end: not).
        act_start = None if getattr(self, "act_label", None) else (act_at or 0.0)
        for event in events:
            if self.priority(event, events, act_start):
                self.event(event, who, act_at)

    # -- event priority

    def priority(self, event, events: list, act_start: float | None = None) -> bool:
        """An event's priority against the other events of its maneuver (`events`); False: the
        event is refused. Where no other event can be running when it starts, the priority
        changes nothing; an override whose start may end others' actions beyond the domains it
        takes has no form in the language (W0802: they run on); a skip waits on the others'
        states (`skip_priority`, once every step is named)."""
        name = event.get("name", "")
        prio = self.raw(event, "priority", required=False)
        if prio == "overwrite":  # OpenSCENARIO 1.0's name of 1.2's override
            prio = "override"
        if prio not in ("override", "skip", "parallel"):
            self.skip(event, f"event '{name}' has " + (f"priority '{prio}'" if prio else "no priority")
                      + ": esmini never starts it", "an event's priority is override, skip or parallel")
            return False
        if prio == "parallel":
            return True
        running = [o for o in events if o is not event and self.may_run_at_start(event, o, prio, events, act_start)]
        if not running:
            return True
        names = ", ".join(f"'{o.get('name', '')}'" for o in running)
        if prio == "override":
            # The language ends a running behaviour only by another on its channel: the others'
            # actions on domains this event does not take run on.
            ours = event_domains(event, running=False) or set()
            self.approx(event, f"event '{name}' has priority override: esmini ends the other events of its maneuver "
                               f"that run when it starts ({names} may), their actions on every domain; here only "
                               "those on a domain of its own actions (" + (", ".join(sorted(ours)) or "none") + ")",
                        "an override whose other events cannot be running when it starts, or whose actions take "
                        "every domain of theirs, is exact")
            return True
        self.skipping.append((event, running, events))
        return True

    def starts_on(self, event, events: list):
        """(event name, state) when an event's start trigger is one StoryboardElementStateCondition on
        an event (or an action of one) of `events`, beside only its own act or story starting; else None."""
        conds = list(event.iterfind("StartTrigger/ConditionGroup/Condition"))
        if len(list(event.iterfind("StartTrigger/ConditionGroup"))) != 1:
            return None
        found = []
        for cond in conds:
            sesc = cond.find("ByValueCondition/StoryboardElementStateCondition")
            kind = self.raw(sesc, "storyboardElementType", required=False) if sesc is not None else None
            if kind in ("act", "story") and self.raw(sesc, "state", required=False) in ("startTransition",
                                                                                         "runningState") \
                    and self.raw(sesc, "storyboardElementRef", required=False) in (
                        getattr(self, "act_name", None), getattr(self, "story_name", None)):
                continue  # its own act (story) has started: true whenever the event is armed
            if kind not in ("event", "action"):
                return None
            ref = self.raw(sesc, "storyboardElementRef", required=False)
            owner = next((e.get("name", "") for e in events if e.get("name") == ref or (
                kind == "action" and any(a.get("name") == ref for a in e.iterfind("Action")))), None)
            found.append((owner, self.raw(sesc, "state", required=False)))
        return found[0] if len(found) == 1 and found[0][0] is not None else None

    def may_run_at_start(self, event, other, prio: str, events: list, act_start: float | None = None) -> bool:
        """Whether `other` may be running when `event` starts, so that the priority makes a
        difference. Provably not: its actions all end as they start; it has ended before `event`
        starts, or starts after it (chains of starts on states: `ended_before`); both start on
        simulation times, `other` no earlier and listed after `event`; `other` starts on a time
        and its lane changes of a given time end before `event`'s time. For an override, also
        not where `event`'s actions take every domain of `other`'s running ones: its start ends
        them whatever the priority (esmini's domain conflict, the twin's behaviour replaced on
        its channel)."""
        theirs = event_domains(other)
        if theirs == set():
            return False
        if other.get("name", "") in self.ended_before(event, events, ()):
            return False
        if event.get("name", "") in self.ended_before(other, events, (), started=True):
            return False
        mine, theirs_at = self.start_time(event), self.start_time(other)
        if mine is not None and (mine == float("-inf") or (theirs_at is not None and theirs_at >= mine)) \
                and events.index(other) > events.index(event) \
                and self.value(event, "maximumExecutionCount", default=1.0) <= 1:
            return False  # (events are started in their order: in one step, it starts first)
        length = self.known_length(other)
        if mine is not None and theirs_at is not None and length is not None and act_start is not None \
                and max(mine, act_start) >= max(theirs_at, act_start) + length + END_MARGIN_S:
            return False  # it ends before this one starts
        ours = event_domains(event, running=False)
        return not (prio == "override" and theirs is not None and ours is not None and theirs <= ours)

    def known_length(self, event) -> float | None:
        """How long an event's actions run [s] where the file says it: lane changes over a time
        (the others end as they start); None otherwise, or when it may run more than once."""
        if self.value(event, "maximumExecutionCount", default=1.0) > 1:
            return None
        out = 0.0
        for action in event.iterfind("Action"):
            leaf = action_leaf(action)
            if at_once(leaf):
                continue
            dyn = child_at(leaf, "LaneChangeActionDynamics") if leaf.tag == "LaneChangeAction" else None
            if dyn is None or dyn.get("dynamicsDimension") != "time":
                return None
            out = max(out, self.value(dyn, "value", units.TIME))
        return out

    def start_time(self, event) -> float | None:
        """The earliest an event can start [s] when its start trigger is only simulation times
        past a value (and its own act or story starting): the largest value (-inf: as its act
        starts); None otherwise. It starts at that time or its act's start, whichever is later
        (or, on a rising edge, never)."""
        out = float("-inf")
        if len(list(event.iterfind("StartTrigger/ConditionGroup"))) > 1:
            return None
        for cond in event.iterfind("StartTrigger/ConditionGroup/Condition"):
            sesc = cond.find("ByValueCondition/StoryboardElementStateCondition")
            time = cond.find("ByValueCondition/SimulationTimeCondition")
            if self.value(cond, "delay", units.TIME, 0.0) != 0.0 \
                    or cond.get("conditionEdge", "none") not in ("none", "rising"):
                return None
            if time is not None and (time.get("rule") or "").startswith("greater"):
                out = max(out, self.value(time, "value"))
            elif sesc is None or self.raw(sesc, "storyboardElementType", required=False) not in ("act", "story") \
                    or self.raw(sesc, "storyboardElementRef", required=False) not in (
                        getattr(self, "act_name", None), getattr(self, "story_name", None)) \
                    or self.raw(sesc, "state", required=False) not in ("startTransition", "runningState"):
                return None
        return out

    def ended_before(self, event, events: list, seen: tuple, started: bool = False) -> set:
        """The events of `events` that have ended when `event` starts, each run once (with
        `started`: those that have at least started): along its start on another event's state."""
        on = self.starts_on(event, events)
        name = event.get("name", "")
        if on is None or name in seen:
            return set()
        ref, state = on
        first = next(e for e in events if e.get("name", "") == ref)
        if self.value(first, "maximumExecutionCount", default=1.0) > 1:
            return set()
        out = self.ended_before(first, events, seen + (name,), started)
        if started or state in ENDED_STATES:
            out.add(ref)
        return out

    def skip_priority(self) -> None:
        """Events of priority skip: their step also waits until no other event of the maneuver
        runs (`... and not (started(A.x) and not ended(A.x))`), asked at each physics step as
        esmini asks the start trigger again. Exact on a start condition without edge, delay or
        duration; otherwise refused."""
        for event, running, events in self.skipping:
            name = event.get("name", "")
            first = self.events.get(name)
            info = self.actors.get(first.actor) if first is not None else None
            at = next((i for i, t in enumerate(info["triggers"]) if t.clause is first.clause), None) \
                if info is not None else None
            step = info["triggers"][at] if at is not None else None
            conds = list(event.iterfind("StartTrigger/ConditionGroup/Condition"))
            if step is None or step.edge or step.delay_s is not None or step.hold_s is not None \
                    or any(c.get("conditionEdge", "none") != "none" or self.value(c, "delay", units.TIME, 0.0)
                           for c in conds) \
                    or len(event.findall("Action")) > 1 \
                    or any(len(o.findall("Action")) > 1 for o in running):
                self.skip(event, f"event '{name}' has priority skip, and its start (an edge, a delay, a duration, "
                                 "several actions, or a step in a group) cannot also wait for the other events "
                                 "of its maneuver to stop running",
                          "a skip event of one action started by a condition or a time translates")
                continue
            states = [self.event_state(o.get("name", ""), "runningState") for o in running]
            if any(s is None for s in states):
                self.skip(event, f"event '{name}' has priority skip, and not every other event of its maneuver that "
                                 "may run when it starts is a step whose state can be read")
                continue
            step = info["triggers"][at]  # (naming the others' steps may have named this one)
            free = all_of([E.Unary(op="not", arg=s) for s in states])
            cond = free if step.condition is None else all_of([step.condition, free])
            info["triggers"][at] = step.model_copy(update={"condition": cond})
            for o in running:
                if any(p is not event and p is not o and (event_domains(p) is None or event_domains(o) is None
                                                          or event_domains(p) & event_domains(o))
                       for p in events):
                    self.approx(event, f"event '{name}' (priority skip) waits for '{o.get('name', '')}' to end; a "
                                       "behaviour replaced before it completes never ends here, where esmini ends "
                                       "its event")
        self.skipping = []

    def event(self, event, who: str, act_at) -> None:
        name = event.get("name", "")
        if name in (self.sidecar or {}).get("group_events", ()):
            return  # a step of a group: the side file has the group (appended in `plan`)
        actions = list(event.iterfind("Action"))
        clauses, lights = [], []
        for action in actions:
            body = only_child(action)
            if body is None:
                continue
            if body.tag == "GlobalAction" and self.global_action(GLOBAL_ACTIONS, body, name, lights):
                continue
            if body.tag != "PrivateAction":
                self.skip(body, f"<{body.tag}> is not translated (private actions are)")
                continue
            if who is None:
                self.skip(body, f"<{first_of(only_child(body), body).tag}> in a maneuver group without actors is "
                                "not translated")
                continue
            inner = only_child(body)
            if inner is None:
                continue
            if inner.tag == "VisibilityAction" and len(actions) == 1:
                # An exported group's anchor (a no-op): the events it starts form one group.
                step = self.start(event.find("StartTrigger"), who, act_at)
                if step is not None and step.after is None:
                    self.anchors[name] = Anchor(who, step.fields)
                return
            exact = (self.sidecar or {}).get("behaviors", {}).get(name)
            clause = ClausePlan.model_validate(exact["clause"]) if exact else self.private_action(inner, who)
            if clause is not None:
                clauses.append(clause)
                if action.get("name"):  # a state of the action: its own step's
                    self.events.setdefault(action.get("name"), EventStep(who, clause))
        if any(c.keyword == "light" for _, c in lights):
            self.global_step("light", event, self.light_event([(el, c) for el, c in lights if c.keyword == "light"]),
                             who, act_at)
        if any(c.keyword == "environment" for _, c in lights):
            self.global_step("environment", event, [c for _, c in lights if c.keyword == "environment"], who, act_at)
        if any(c.keyword == "set" for _, c in lights):
            self.global_step("variable", event, [c for _, c in lights if c.keyword == "set"], who, act_at)
        if not clauses:
            if actions and not lights and who is not None and all(
                    any(child_at(a, "PrivateAction", t) is not None for t in sorted(INSTANT_ACTIONS)) for a in actions):
                for key in [name] + [a.get("name") for a in actions if a.get("name")]:
                    self.instant.setdefault(key, InstantEvent(who, event, act_at))
            return
        trigger = event.find("StartTrigger")
        step = self.start(trigger, who, act_at, name)
        if step is None:
            return
        fields = step.fields
        at_once = step.after is None and set(fields) <= {"at_s"} \
            and float(fields.get("at_s", E.Num(value=0.0)).value) == 0
        for clause, el, ref in self.relative_paths:
            if not at_once and any(c is clause for c in clauses):
                # esmini places such a trajectory where the entity is when the action starts.
                self.skip(el, f"a trajectory relative to '{ref}' in an event that starts after time 0 is not "
                              "translated (its points would be placed from where the entity starts the run)",
                          "a trajectory relative to an entity translates from the start (Init, or an event at "
                          "time 0)")
                clauses = [c for c in clauses if c is not clause]
        if not clauses:
            return
        clauses = speed_into_trajectory(clauses)
        if len(clauses) > 1:
            self.approx(event, f"event '{name}' starts {len(clauses)} actions: one step each, same start")
        runs = int(self.value(event, "maximumExecutionCount", default=1.0))
        if runs > 1:
            # It starts again when its actions have ended and its condition counts again.
            if fields.get("condition") is None and not fields.get("at_s") and step.after is None \
                    and len(clauses) == 1 and getattr(self, "act_label", None):
                # No start condition of its own: true whenever armed, which is once its act has started.
                fields = {**fields, "condition": step_state("startTransition", f"{who}.{self.act_label}")}
            if step.after is not None or fields.get("condition") is None or len(clauses) > 1:
                self.skip(event, f"an event that runs up to {runs} times without a start condition of its own, or "
                                 "with several actions, is not translated",
                          "one action started by a condition translates (`when C repeat N`)")
                return
            fields = {**fields, "repeat": min(runs, 1_000_000)}
        self.event_order.append(name)
        for clause in clauses:
            self.events.setdefault(name, EventStep(who, clause))
            if step.after is not None:
                self.pending.append(PendingEvent(name, who, step.after, clause))
            elif not fields:
                self.actors[who]["behaviors"].append(clause)
            else:
                self.actors[who]["triggers"].append(TriggerPlan(clause=clause, **fields))

    # Steps of an event's global actions: the list each kind goes to, and what it may start on.
    GLOBAL_STEPS = {"light": ("light_steps", "a light step", "a lights block's steps start"),
                    "environment": ("environment_steps", "an environment step", "an environment step starts"),
                    "variable": ("variable_steps", "a variable step", "a variable step starts")}

    def global_step(self, kind: str, event, clauses: list[ClausePlan], who, act_at) -> None:
        """The lights, environment or variable step of an event's global actions."""
        steps, noun, starts = self.GLOBAL_STEPS[kind]
        step = self.start(event.find("StartTrigger"), who, act_at, event.get("name", ""))
        if step is None:
            return
        if step.after is not None:
            self.skip(step.after.cond, f"{kind} step '{event.get('name')}' starts on another event: not translated",
                      f"{starts} at a time, after a delay or on a condition")
            return
        if int(self.value(event, "maximumExecutionCount", default=1.0)) > 1:
            self.skip(event, f"{noun} that runs more than once is not translated")
            return
        getattr(self, steps).extend(TriggerPlan(clause=c, **step.fields) for c in clauses)

    def start(self, trigger, who: str, act_at, event: str = ""):
        """How the step starts (a Start: the fields of a TriggerPlan, or after another event); None:
        dropped."""
        groups = list(trigger.iterfind("ConditionGroup")) if trigger is not None else []
        alternatives, at_s, holds, edges, after_s = [], act_at, [], [], None
        stand_still = len(self.stand_still)
        for group in groups:
            conj = []
            for cond in group.iterfind("Condition"):
                sesc = cond.find("ByValueCondition/StoryboardElementStateCondition")
                if sesc is not None and self.raw(sesc, "storyboardElementType") in ("act", "story") \
                        and self.raw(sesc, "state") in ("startTransition", "runningState") \
                        and self.raw(sesc, "storyboardElementRef") in (getattr(self, "act_name", None),
                                                                       getattr(self, "story_name", None)) \
                        and self.value(cond, "delay", units.TIME, 0.0) == 0.0:
                    continue  # the event's own act (story) has started: true whenever the event is armed
                if sesc is not None and len(groups) == 1 and len(list(group)) == 1:
                    if self.raw(sesc, "storyboardElementType") in ("event", "action"):
                        return Start({}, AfterEvent(self.raw(sesc, "storyboardElementRef"),
                                                    self.value(cond, "delay", units.TIME, 0.0),
                                                    self.raw(sesc, "state"), cond))
                time = cond.find("ByValueCondition/SimulationTimeCondition")
                if time is not None and (time.get("rule") or "").startswith("greater") and len(groups) == 1:
                    value = self.value(time, "value")
                    if self.carla:  # ScenarioRunner: counted from when the event's act started
                        if getattr(self, "act_label", None):
                            after_s = max(after_s or 0.0, value)
                        else:
                            at_s = max(at_s or 0.0, (act_at or 0.0) + value)
                    else:
                        at_s = max(at_s or 0.0, value) if value > 0 else at_s
                    continue
                # A condition held for a duration (OffroadCondition) sets `cond_hold`: the step's
                # `for D`, in a trigger of that one condition only.
                self.hold_allowed, self.cond_hold = len(groups) == 1 and len(list(group)) == 1, None
                self.cond_hold_edge = False  # the condition's edge is on the held condition (runtime order)
                formula = self.condition(cond, who)
                self.hold_allowed = False
                if formula is None:
                    return None
                if self.cond_hold is not None:
                    if self.value(cond, "delay", units.TIME, 0.0) > 0:
                        self.skip(cond, "a condition held for a duration with a delay is not translated")
                        return None
                    edge = EDGES.get(cond.get("conditionEdge", "none")) if self.cond_hold_edge and not self.carla \
                        else None
                    if getattr(self, "act_condition", None) is not None:
                        formula = all_of([self.act_condition, formula])
                    return Start({**({"at_s": E.Num(value=at_s)} if at_s is not None else {}),
                                  "condition": formula, "hold_s": E.Num(value=self.cond_hold),
                                  **({"edge": edge} if edge else {})})
                conj.append(formula)
                if self.carla and self.value(cond, "delay", units.TIME, 0.0) > 0:
                    self.approx(cond, "a condition's delay as OpenSCENARIO reads it (the step fires D after the "
                                      "condition held); ScenarioRunner waits D, then checks the condition")
                holds.append((self.value(cond, "delay", units.TIME, 0.0), cond))
                edges.append((EDGES.get(cond.get("conditionEdge", "none")), cond))
            if conj:
                alternatives.append(all_of(conj))
        fields = {}
        if at_s is not None:
            fields["at_s"] = E.Num(value=at_s)
        if after_s is not None:
            fields["after_s"] = E.Num(value=after_s)
        if getattr(self, "act_condition", None) is not None:  # (CARLA: its act's start, `story`)
            alternatives = [all_of([self.act_condition, a]) for a in alternatives] or [self.act_condition]
        if self.carla:
            edges = []  # ScenarioRunner reads no conditionEdge: a condition counts whenever it holds
        if alternatives:
            fields["condition"] = any_of(alternatives)
        # One condition (the usual case): its edge and delay exactly. Several: the step's edge
        # and delay act on the whole formula, exact when all conditions agree.
        if any(e for e, _ in edges):
            if len(edges) > 1:
                self.approx(edges[0][1], "several conditions with edges: the edge applies to the whole start "
                                         "condition")
            fields["edge"] = next(e for e, _ in edges if e)
        delays = sorted({d for d, _ in holds})
        if delays and delays[-1] > 0:
            delay = delays[-1]
            if len(delays) > 1:
                self.approx(holds[0][1], f"conditions with different delays: the step fires {delay:g} s after its "
                                         "whole start condition")
            if (self.sidecar or {}).get("holds", {}).get(event) == delay:  # an exported `when C for D`
                fields["hold_s"] = E.Num(value=delay)
                fields.pop("edge", None)
            else:
                fields["delay_s"] = E.Num(value=delay)
        hold = self.stand_still_hold(stand_still, sum(len(list(g.iterfind("Condition"))) for g in groups))
        if hold is not None and "hold_s" not in fields:
            fields["hold_s"] = hold
        return Start(fields)

    # -- sequences: an event started by another event of the same actor

    def link_sequences(self) -> None:
        grouped: dict[str, list] = {}
        for p in self.pending:
            name, who, clause, (ref, delay, state, cond) = p.name, p.actor, p.clause, p.after.fields()
            if ref in self.anchors and self.anchors[ref].actor == who:
                grouped.setdefault(ref, []).append(TriggerPlan(clause=clause, after_s=E.Num(value=delay)
                                                               if delay else None))
                self.events[name] = EventStep(who, clause)
        for ref, steps in grouped.items():
            anchor = self.anchors[ref]
            self.actors[anchor.actor]["triggers"].append(TriggerPlan(group=GroupPlan(mode="parallel", steps=steps),
                                                                     **anchor.fields))
        other_actor = []  # after the sequences are built: a named step never gets lifted
        for p in self.pending:
            name, who, clause, (ref, delay, state, cond) = p.name, p.actor, p.clause, p.after.fields()
            if ref in grouped:
                continue
            first = self.events.get(ref)
            # Another actor's event, or the end of one of its own whose length the settings do
            # not give (a synchronisation, a speed change at a rate): on its step's state.
            if first is not None and state in STATE_SIGNAL and (first.actor != who or (
                    state != "startTransition" and not duration_of(first.clause))):
                other_actor.append((name, who, (ref, delay, state, cond), clause, first))
                continue
            if first is None or first.actor != who:
                self.skip(cond, f"event '{name}' starts on '{ref}', "
                                + ("not an event of the same actor" if first else "which is not translated"),
                          "a step after another actor's event has no form in the language")
                continue
            after = delay
            if state in ("endTransition", "completeState"):
                after += duration_of(first.clause)
            info = self.actors[who]
            prev_clause = first.clause
            # Lift the first step into a sequence that also starts this one.
            for i, tr in enumerate(info["triggers"]):
                if tr.clause == prev_clause or (tr.group and tr.group.steps and tr.group.steps[0].clause ==
                                                prev_clause):
                    steps = list(tr.group.steps) if tr.group else [TriggerPlan(clause=prev_clause)]
                    steps.append(TriggerPlan(clause=clause, after_s=E.Num(value=after) if after else None))
                    # The step's start (its hold and name too) now starts the sequence.
                    info["triggers"][i] = tr.model_copy(update={"clause": None,
                                                                "group": GroupPlan(mode="sequence", steps=steps)})
                    break
            else:
                if prev_clause in info["behaviors"]:
                    info["triggers"].append(TriggerPlan(after_s=E.Num(value=after), clause=clause)
                                            if after else TriggerPlan(at_s=E.Num(value=0.0), clause=clause))
                else:
                    self.skip(cond, f"event '{name}' follows '{ref}' in a way the language cannot say")
                    continue
            self.events[name] = EventStep(who, clause)
        for name, who, (ref, delay, state, cond), clause, first in other_actor:
            if not self.after_other_actor(who, ref, delay, state, cond, clause, first):
                self.skip(cond, f"event '{name}' starts on '{ref}' of '{first.actor}', which is not a step",
                          "only an event that starts a step can be named for `started`/`ended`")
                continue
            self.events[name] = EventStep(who, clause)

    def after_other_actor(self, who, ref, delay, state, cond, clause, first) -> bool:
        """An event on another actor's event: that event's step gets a name and this one
        starts on its state (`when ended(lead.brake) delayed D then ...`)."""
        state_of = self.event_state(ref, state)
        if state_of is None:
            return False
        self.actors[who]["triggers"].append(TriggerPlan(condition=state_of, clause=clause,
                                                        delay_s=E.Num(value=delay) if delay else None))
        return True

    def event_state(self, ref: str, state: str):
        """`started(A.x) > 0` / `ended(A.x) > 0` for an event, naming its step (an event
        at time 0 becomes a named step `after 0 s`); None if the event has no step."""
        first = self.events.get(ref)
        if first is None and state in STATE_SIGNAL and ref in (self.sidecar or {}).get("group_events", ()):
            # A step of an exported group (the side file has the group): its name is the event's.
            for who, groups in sorted(self.sidecar.get("groups", {}).items()):
                if any(s.label == ref for g in groups for s in steps_of(TriggerPlan.model_validate(g))):
                    return step_state(state, f"{who}.{ref}")
        if first is None or state not in STATE_SIGNAL:
            return None
        other = first.actor
        info = self.actors[other]
        taken = {tr.label for a in self.actors.values() for t in a["triggers"] for tr in steps_of(t) if tr.label}
        if not any(tr.clause == first.clause for t in info["triggers"] for tr in steps_of(t)):
            j = next((j for j, c in enumerate(info["behaviors"]) if c == first.clause), None)
            if j is None:
                return None
            clause = info["behaviors"].pop(j)
            info["triggers"].append(TriggerPlan(after_s=E.Num(value=0.0), clause=clause))
        found: list[str] = []
        # The event's own step (two events may start equal actions), else one that starts the same.
        for same in ((lambda a, b: a is b), None):
            info["triggers"] = [labelled(t, first.clause, safe_name(ref, taken), found, same)
                                for t in info["triggers"]]
            if found:
                break
        label = found[0]
        return step_state(state, f"{other}.{label}")

    def instant_state(self, ref: str, state: str):
        """A state of an event (or action) that does nothing in the twin but happen at once: it
        starts, runs and ends at its start, so its state is the state of the event that starts
        it, and the delay of that start [s]. (None, 0): its start is not on another event's state."""
        got = self.instant.get(ref)
        if got is None or state not in STATE_SIGNAL:
            return None, 0.0
        step = self.start(got.el.find("StartTrigger"), got.actor, got.act_at, got.el.get("name", ""))
        if step is None or step.after is None or step.after.ref in self.instant:
            return None, 0.0
        if step.after.cond.get("conditionEdge", "none") not in ("none", "rising"):
            return None, 0.0  # a transition's falling edge: one step after it (not said)
        return self.event_state(step.after.ref, step.after.state), step.after.delay

    def duration_group(self, group) -> bool:
        """Whether a stop condition group is a simulation time alone (the run's duration)."""
        conds = list(group.iterfind("Condition"))
        time = conds[0].find("ByValueCondition/SimulationTimeCondition") if len(conds) == 1 else None
        return time is not None and (time.get("rule") or "").startswith("greater")

    def end_trigger(self, trigger) -> None:
        """The storyboard's stop trigger beyond its simulation time (the run's duration):
        `end when ...`. Element states of events and maneuvers, and entity conditions."""
        if trigger is None:
            return
        alternatives, delays, edges, at_s = [], [], [], None
        groups = list(trigger.iterfind("ConditionGroup"))
        stand_still = len(self.stand_still)
        for group in groups:
            conj, timed = [], None
            for cond in group.iterfind("Condition"):
                if (cond.get("name") or "").startswith("criteria_"):
                    continue  # CARLA ScenarioRunner's pass criteria: oracles (pass_criteria)
                time = cond.find("ByValueCondition/SimulationTimeCondition")
                if time is not None and (time.get("rule") or "").startswith("greater"):
                    timed = self.value(time, "value")  # alone: the duration
                    continue
                sesc = cond.find("ByValueCondition/StoryboardElementStateCondition")
                if sesc is not None:
                    kind, ref, state = (self.raw(sesc, "storyboardElementType"), self.raw(sesc, "storyboardElementRef"),
                                        self.raw(sesc, "state"))
                    events = [ref] if kind in ("event", "action") else self.maneuvers.get(ref) \
                        if kind == "maneuver" and state in ("endTransition", "completeState") else \
                        self.act_events.get(ref) if kind == "act" and state in ("endTransition", "completeState") \
                        else None
                    parts = [self.event_state(e, state) for e in events] if events else [None]
                    extra = 0.0  # an event that does nothing but start: the state of the event starting it
                    if kind in ("event", "action") and parts == [None]:
                        instant, extra = self.instant_state(ref, state)
                        parts = [instant]
                    if not parts or any(p is None for p in parts):
                        self.skip(cond, f"a stop trigger on the {kind} '{ref}' ({state}) is not translated",
                                  "events and maneuvers that translate to steps are")
                        return
                    conj.append(all_of(parts))
                else:
                    extra = 0.0
                    formula = self.condition(cond, "ego")
                    if formula is None:
                        return
                    conj.append(formula)
                delays.append((self.value(cond, "delay", units.TIME, 0.0) + extra, cond))
                edges.append((EDGES.get(cond.get("conditionEdge", "none")), cond))
            if conj and timed is not None:
                # (a group of a simulation time alone beside it is the run's duration: `stop_trigger`)
                if len([g for g in groups if list(g) and not self.duration_group(g)]) > 1:
                    self.skip(group, "a stop condition group that mixes the simulation time with other conditions, "
                                     "beside other groups, is not translated")
                    return
                at_s = timed  # `end at T when C`
            if conj:
                alternatives.append(all_of(conj))
        if not alternatives:
            return
        fields = {"condition": any_of(alternatives)}
        if at_s is not None and at_s > 0:
            fields["at_s"] = E.Num(value=at_s)
        if any(e for e, _ in edges):
            if len(edges) > 1:
                self.approx(edges[0][1], "several stop conditions with edges: the edge applies to the whole condition")
            fields["edge"] = next(e for e, _ in edges if e)
        if delays and max(d for d, _ in delays) > 0:
            if len({d for d, _ in delays}) > 1:
                self.approx(delays[0][1], "stop conditions with different delays: the run ends the longest after")
            fields["delay_s"] = E.Num(value=max(d for d, _ in delays))
        hold = self.stand_still_hold(stand_still, len(delays))
        if hold is not None:
            fields["hold_s"] = hold
        self.end = TriggerPlan(**fields)
