"""A RunSpec bound once: the concrete scenario of plain numbers the twin reads.

The plan keeps parameter-dependent values as expression trees; `bind(spec)` evaluates
every one of them for the spec's parameters, once, before the loop starts: actor
placements, behaviour/sensor/stack settings, script timings and conditions, oracle
formulas. The loop, the scripts and the judge read only the bound scenario, so no
parameter expression is evaluated twice and nothing downstream needs the parameters.
"""

from __future__ import annotations

from dataclasses import dataclass

from addt_dsl import units
from addt_dsl.expr import (Expr, Temporal, Until, eval_param_expr, params_used, signals_used, substitute_params,
                           walk, window_exprs, window_problem)
from addt_dsl.plan import (ActorPlan, ClausePlan, ConcreteFault, ControllerPlan, GroupPlan, OraclePlan, RoadPlan,
                           RunSpec, ScenarioPlan, SignalPlan, TriggerPlan, resolve_settings)
from addt_dsl.vehicles import DEFAULT_MU, VEHICLES


@dataclass(frozen=True)
class BoundClause:
    """A registered element (behaviour, sensor, stack) with its settings resolved."""

    keyword: str
    name: str
    settings: dict


@dataclass(frozen=True)
class BoundGroup:
    mode: str  # sequence | parallel
    steps: tuple[BoundStep, ...]


@dataclass(frozen=True)
class BoundStep:
    """A script step (`plan.TriggerPlan`) with its times resolved and its condition's
    parameters substituted."""

    clause: BoundClause | None
    condition: Expr | None
    at_s: float | None
    after_s: float
    group: BoundGroup | None
    hold_s: float = 0.0  # the condition must have held this long [s]
    label: str | None = None  # a named step: its state is recorded as `actor.label`
    edge: str | None = None  # rising | falling | changing: the condition counts where it changes
    delay_s: float = 0.0  # fires this long after the condition counted [s]
    repeat: int = 1  # firings in all: armed again when its behaviour has ended


@dataclass(frozen=True)
class BoundActor:
    name: str
    vehicle: str
    road: str
    lane: int
    s: float  # station along the road [m]
    speed: float  # initial speed [m/s]
    offset: float  # from the lane centre, left positive [m]
    length_m: float
    width_m: float
    height_m: float  # body height [m]: the box lidar rays and cameras meet
    mass_kg: float
    wheelbase_m: float
    mu: float  # tyre-road friction (ego dynamics)
    behaviors: tuple[BoundClause, ...]
    steps: tuple[BoundStep, ...]
    sensors: tuple[BoundClause, ...]
    stack: BoundClause | None
    route: tuple[str, ...] = ()  # road ids in driving order; () = the road it is placed on
    yaw: float = 0.0  # body yaw relative to the driving direction [rad]
    ignore_lights: bool = False  # runs red lights
    reverse: bool = False  # drives against its lane's driving direction
    stop_at_road_end: bool = False  # stops at the end of its road or route

    @property
    def scripted(self) -> bool:
        """Moved by its behaviours and steps (`ActorPlan.scripted`)."""
        return bool(self.behaviors or self.steps)


@dataclass(frozen=True)
class BoundOracle:
    name: str
    severity: str
    formula: Expr  # no parameters left


@dataclass(frozen=True)
class BoundController:
    """A traffic-light controller with its program's times resolved [s]."""

    name: str
    road: str
    signals: tuple[str, ...]
    green_s: float
    yellow_s: float
    red_s: float
    offset_s: float


@dataclass(frozen=True)
class BoundScenario:
    name: str
    duration_s: float
    step_s: float
    seed: int
    roads: tuple[RoadPlan, ...]
    ego: BoundActor
    agents: tuple[BoundActor, ...]
    faults: tuple[ConcreteFault, ...]
    oracles: tuple[BoundOracle, ...]
    signals: tuple[SignalPlan, ...] = ()
    controllers: tuple[BoundController, ...] = ()
    light_steps: tuple[BoundStep, ...] = ()
    environment: tuple[BoundClause, ...] = ()
    environment_steps: tuple[BoundStep, ...] = ()
    variables: tuple[tuple[str, float], ...] = ()  # scenario variables and their first values
    variable_steps: tuple[BoundStep, ...] = ()
    end: BoundStep | None = None  # `end when ...`: the run ends where it fires

    def road(self, name: str) -> RoadPlan:
        return next(r for r in self.roads if r.name == name)




def bind(spec: RunSpec) -> BoundScenario:
    plan, params = spec.plan, spec.params
    return BoundScenario(
        name=plan.name, duration_s=plan.duration_s, step_s=plan.step_s, seed=spec.seed, roads=tuple(plan.roads),
        ego=_actor(plan.ego, params), agents=tuple(_actor(a, params) for a in plan.agents),
        faults=tuple(spec.faults),
        oracles=tuple(_oracle(o, params, plan) for o in plan.oracles),
        environment=tuple(_clause(c, params) for c in plan.environment),
        environment_steps=tuple(bind_step(t, params) for t in plan.environment_steps),
        signals=tuple(plan.signals), controllers=tuple(_controller(c, params) for c in plan.controllers),
        light_steps=tuple(bind_step(t, params) for t in plan.light_steps),
        variables=tuple((v.name, v.value) for v in plan.variables),
        variable_steps=tuple(bind_step(t, params) for t in plan.variable_steps),
        end=bind_step(plan.end, params) if plan.end is not None else None)


class WindowError(ValueError):
    """An oracle's window over parameters is invalid with this run's values (a sampled
    parameter the compiler could not check for every run)."""


def _oracle(o: OraclePlan, params: dict[str, float], plan: ScenarioPlan) -> BoundOracle:
    """The oracle with its parameters substituted; each window over parameters is checked
    with this run's values as the compiler checks constant ones (`expr.window_problem`)."""
    formula = substitute_params(o.formula, params)
    for plain, bound in zip(_windowed(o.formula), _windowed(formula)):
        problem = window_problem(bound.lo_s, bound.hi_s, plan.duration_s) if window_exprs(plain) else None
        if problem is not None:
            used = sorted(set().union(*(params_used(b) for b in window_exprs(plain))))
            dims = {p.name: units.DIMENSIONS_BY_NAME.get(p.dimension) for p in plan.params}
            values = ", ".join(f"{n} = {params[n]:g} {units.CANONICAL_UNIT.get(dims.get(n), '')}".rstrip()
                               for n in used)
            hi = "the end" if bound.hi_s is None else f"{bound.hi_s:g} s"
            raise WindowError(f"oracle '{o.name}': {problem[1]}: its window is [{bound.lo_s:g} s, {hi}] "
                              f"with {values}")
    return BoundOracle(o.name, o.severity, formula)


def _windowed(formula: Expr) -> list:
    return [n for n in walk(formula) if isinstance(n, (Temporal, Until))]


def _controller(c: ControllerPlan, params: dict[str, float]) -> BoundController:
    return BoundController(c.name, c.road, tuple(c.signals), _value(c.green_s, params), _value(c.yellow_s, params),
                           _value(c.red_s, params), _value(c.offset_s, params))


def _value(expr: Expr | None, params: dict[str, float], default: float = 0.0) -> float:
    return default if expr is None else float(eval_param_expr(expr, params))


def _clause(c: ClausePlan, params: dict[str, float]) -> BoundClause:
    """Settings as numbers; a live setting that reads signals stays an expression (its
    parameters substituted), evaluated on the current state at every step."""
    live = {k: substitute_params(v, params) for k, v in c.settings.items()
            if not isinstance(v, (str, list)) and signals_used(v)}
    fixed = resolve_settings({k: v for k, v in c.settings.items() if k not in live}, params)
    return BoundClause(c.keyword, c.name, {k: live.get(k, fixed.get(k)) for k in c.settings})


def bind_step(t: TriggerPlan, params: dict[str, float]) -> BoundStep:
    return BoundStep(
        clause=_clause(t.clause, params) if t.clause is not None else None,
        condition=substitute_params(t.condition, params) if t.condition is not None else None,
        at_s=_value(t.at_s, params) if t.at_s is not None else None,
        after_s=_value(t.after_s, params),
        group=_group(t.group, params) if t.group is not None else None,
        hold_s=_value(t.hold_s, params), label=t.label, edge=t.edge, delay_s=_value(t.delay_s, params),
        repeat=t.repeat or 1)


def _group(g: GroupPlan, params: dict[str, float]) -> BoundGroup:
    return BoundGroup(g.mode, tuple(bind_step(s, params) for s in g.steps))


def _actor(a: ActorPlan, params: dict[str, float]) -> BoundActor:
    return BoundActor(
        name=a.name, vehicle=a.vehicle, road=a.road, lane=int(round(_value(a.lane, params))), s=_value(a.s, params),
        speed=_value(a.speed, params), offset=_value(a.offset, params), length_m=a.length_m, width_m=a.width_m,
        height_m=a.height_m if a.height_m is not None else VEHICLES[a.vehicle].height_m,
        mass_kg=a.mass_kg, wheelbase_m=a.wheelbase_m, mu=_value(a.mu, params, DEFAULT_MU),
        behaviors=tuple(_clause(c, params) for c in a.behaviors),
        steps=tuple(bind_step(t, params) for t in a.triggers),
        sensors=tuple(_clause(c, params) for c in a.sensors),
        stack=_clause(a.stack, params) if a.stack is not None else None, route=tuple(a.route),
        yaw=_value(a.yaw, params), ignore_lights=a.ignore_lights,
        reverse=a.reverse, stop_at_road_end=a.stop_at_road_end)
