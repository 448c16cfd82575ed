"""The execution plan: what the compiler produces and the runtime consumes.

`ScenarioPlan` is pydantic, JSON-serialisable, versioned, SI units only. Values that
depend on parameters stay `Expr` trees; a `RunSpec` pins one parameter assignment, a
seed and the concrete fault schedule, and fully determines a run.
"""

from __future__ import annotations

import hashlib
import json
from typing import ClassVar, Literal, Union

from pydantic import BaseModel, ConfigDict, Field

from addt_dsl.expr import Expr, Num, Param, eval_param_expr
from addt_dsl.fingerprint import code_fingerprint
from addt_dsl.vehicles import DEFAULT_MASS_KG, DEFAULT_WHEELBASE_M, VEHICLES

# Bump when a plan written by this version cannot be read by the previous one.
SCHEMA_VERSION = "2"

SettingValue = Union[Expr, str, list[Expr]]


class _Model(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


class SegmentPlan(_Model):
    """One planView geometry element of an inline road; SI units."""

    kind: Literal["line", "arc", "spiral", "param_poly3"]
    length_m: float
    curvature_per_m: float = 0.0
    curv_start_per_m: float = 0.0
    curv_end_per_m: float = 0.0
    coefficients: list[float] = Field(default_factory=list)  # param_poly3: aU..dU, aV..dV


class RoadPlan(_Model):
    name: str
    source: Literal["inline", "xodr"]
    segments: list[SegmentPlan] = Field(default_factory=list)
    left_lanes: int = 0
    right_lanes: int = 1
    lane_width_m: float = 3.5
    lane_offset_m: float = 0.0
    xodr_file: str | None = None  # display name of the imported file
    xodr_text: str | None = None  # embedded, so a RunSpec needs no file system
    xodr_road_id: str | None = None


class ParamPlan(_Model):
    name: str
    dimension: str  # units.DIMENSION_NAMES value
    default: float
    low: float | None = None
    high: float | None = None
    # addt_dsl/distributions.py: uniform, normal, lognormal, poisson, histogram, choice
    distribution: Literal["uniform", "normal", "lognormal", "poisson", "histogram", "choice"] = "uniform"
    mean: float | None = None
    sd: float | None = None
    choices: list[float] = Field(default_factory=list)
    bins: list[float] = Field(default_factory=list)  # a histogram's bin edges (SI)
    weights: list[float] = Field(default_factory=list)  # a histogram's bins' or a choice's weights
    integer: bool = False


class AssumptionPlan(_Model):
    """A validity condition on parameters: a sample that breaks it is rejected, not failed.

    `name` is the label of `assume NAME: expr` ("" when unnamed); reports count
    rejections per `name or text`."""

    text: str
    expr: Expr
    name: str = ""


class ClausePlan(_Model):
    """A registered element with its settings: `behavior cruise speed 12 m/s`."""

    keyword: str
    name: str
    settings: dict[str, SettingValue] = Field(default_factory=dict)


class TriggerPlan(_Model):
    """One step of an agent's script.

    A step is *armed* (top-level steps at time 0; steps of a group as the group says),
    then *fires* at the first physics step where all its start conditions hold:
    `after_s` has passed since it was armed, the time is at least `at_s`, and
    `condition` holds on the current state (for `hold_s` without a break, when given). Firing
    starts `clause` (a behaviour) and arms `group`. A step is *done* once it fired and its group (if any) is done.
    Source: `at 5 s behavior brake`, `after 2 s ...`, `when gap(ego, lead) < 20 m then ...`.
    """

    condition: Expr | None = None  # formula over signals, no temporal operators
    clause: ClausePlan | None = None
    at_s: Expr | None = None  # earliest simulated time [s]
    after_s: Expr | None = None  # delay after arming [s]
    group: GroupPlan | None = None
    # `when C for D`: C must have held at every step for D [s] (past-time `historically`).
    hold_s: Expr | None = None
    # `when rising C`: the condition counts only where it changes (OpenSCENARIO conditionEdge):
    # rising false -> true, falling true -> false, changing either; never at its first evaluation.
    edge: Literal["rising", "falling", "changing"] | None = None
    # `when C delayed D`: fires D [s] after the condition (its edge) first counted
    # (OpenSCENARIO's condition delay).
    delay_s: Expr | None = None
    # `when C repeat N`: armed again once the behaviour it started has ended, up to N
    # firings in all (OpenSCENARIO's maximumExecutionCount); None: once.
    repeat: int | None = None
    # `brake_hard: at 3 s ...`: a named step, whose state `started(lead.brake_hard)` and
    # `ended(lead.brake_hard)` read; unique per actor.
    label: str | None = None


class GroupPlan(_Model):
    """Steps armed together (`parallel`: all at once; done when all are done) or one
    after another (`sequence`: each armed when the previous one is done)."""

    mode: Literal["sequence", "parallel"]
    steps: list[TriggerPlan]


TriggerPlan.model_rebuild()


class ActorPlan(_Model):
    name: str
    vehicle: Literal[tuple(VEHICLES)]  # type: ignore[valid-type]  # the catalogue's kinds
    road: str
    lane: Expr
    s: Expr  # station along the road [m]
    speed: Expr  # initial speed [m/s]
    length_m: float
    width_m: float
    height_m: float | None = None  # body height [m] (None: the vehicle kind's; the compiler fills it in)
    mass_kg: float = DEFAULT_MASS_KG
    wheelbase_m: float = DEFAULT_WHEELBASE_M
    behaviors: list[ClausePlan] = Field(default_factory=list)
    triggers: list[TriggerPlan] = Field(default_factory=list)
    sensors: list[ClausePlan] = Field(default_factory=list)
    stack: ClausePlan | None = None
    goal_s: Expr | None = None
    mu: Expr | None = None  # tyre-road friction coefficient of the ego dynamics (None: vehicles.DEFAULT_MU)
    offset: Expr | None = None  # start offset from the lane centre, left positive [m]
    # Road ids of the actor's route through an imported network, connecting roads included
    # (`route 1 -> left -> 3` expanded by the compiler); empty: the road it is placed on.
    route: list[str] = Field(default_factory=list)
    yaw: Expr | None = None  # body yaw relative to the lane's driving direction [rad] (None: 0)
    ignore_lights: bool = False  # runs red lights (agents otherwise stop at red and yellow)
    reverse: bool = False  # drives against its lane's OpenDRIVE driving direction (`direction reverse`)
    stop_at_road_end: bool = False  # stops at the end of its road or route (`at_road_end stop`)

    @property
    def scripted(self) -> bool:
        """Moved by its behaviours and steps (every agent; an ego that has any), not by a stack."""
        return bool(self.behaviors or self.triggers)


# Traffic-light states as numbers (traces and formulas: `light(west) == red`), and the state
# change that hands a light back to its phase program.
LIGHT_STATES = {"green": 0.0, "yellow": 1.0, "red": 2.0}
LIGHT_PROGRAM = "program"


class SignalPlan(_Model):
    """A traffic signal declared on an inline road: `signal NAME road R at S [lane L]`.
    Imported maps bring their own (`<signal dynamic="yes">`)."""

    name: str
    road: str  # the scenario road it stands on
    s_m: float  # its stop line: station along the road [m]
    lanes: list[int] = Field(default_factory=list)  # lanes it governs; empty: every lane driven along +s


class ControllerPlan(_Model):
    """Signals that switch together and their phase program (OpenSCENARIO's
    TrafficSignalController with one green/yellow/red cycle): green from `offset_s`, then
    yellow, then red, repeating every green + yellow + red seconds."""

    name: str
    road: str  # the scenario road (its map) the signals are on
    signals: list[str]  # signal ids on that map (inline roads: `SignalPlan` names)
    green_s: Expr
    yellow_s: Expr
    red_s: Expr
    offset_s: Expr


class FaultPlan(_Model):
    kind: str
    target: str  # sensor name or dotted stack path (`perception.backbone`)
    start_s: Expr
    end_s: Expr | None  # None: to the end of the run
    settings: dict[str, SettingValue] = Field(default_factory=dict)
    seed: int | None = None
    source: str = ""  # file:line, for reports
    # `when C [delayed D] [for W]`: a step's start (no clause, fires once) that opens the window
    # where it fires; `start_s` and `end_s` then count from that instant (0 and W, or None).
    opens: TriggerPlan | None = None


class OraclePlan(_Model):
    name: str
    severity: Literal["hard", "warn"] = "hard"
    formula: Expr
    text: str = ""


class GridAxis(_Model):
    param: str
    values: list[float]


class CaseAxis(_Model):
    """Listed combinations (`cases a in [1, 2] m, b in [3, 4] s`; OpenSCENARIO's
    ValueSetDistribution): row i sets each parameter to its i-th value. One axis of the
    grid's product, after the `grid` axes."""

    params: list[str]
    rows: list[list[float]]  # SI units, one value per parameter


class SamplerPlan(_Model):
    kind: Literal["random", "halton", "lhs"]
    count: int
    seed: int = 0


class SweepPlan(_Model):
    grid: list[GridAxis] = Field(default_factory=list)
    cases: list[CaseAxis] = Field(default_factory=list)
    sampler: SamplerPlan | None = None
    repeat: int = 1
    seed: int = 0
    max_rejections: int = 1000


class VariablePlan(_Model):
    """A scenario variable: a number steps set during the run and conditions read (`var(NAME)`)."""

    name: str
    value: float  # its value at the start


class ScenarioPlan(_Model):
    schema_version: Literal["2"] = SCHEMA_VERSION
    name: str
    description: str = ""
    source_file: str = ""
    duration_s: float
    step_s: float = 0.01
    seed: int = 0
    # Pins the seed of every run (replay files written by the printer); None: run seeds
    # derive from (seed, sweep seed, cell, repeat).
    run_seed: int | None = None
    roads: list[RoadPlan]
    params: list[ParamPlan] = Field(default_factory=list)
    assumptions: list[AssumptionPlan] = Field(default_factory=list)
    ego: ActorPlan
    agents: list[ActorPlan] = Field(default_factory=list)
    faults: list[FaultPlan] = Field(default_factory=list)
    oracles: list[OraclePlan] = Field(default_factory=list)
    sweep: SweepPlan = Field(default_factory=SweepPlan)
    # Traffic lights (`lights { }`): inline signals, controllers with phase programs, and
    # state changes as steps (clauses `light CONTROLLER state S`), armed at time 0.
    signals: list[SignalPlan] = Field(default_factory=list)
    controllers: list[ControllerPlan] = Field(default_factory=list)
    light_steps: list[TriggerPlan] = Field(default_factory=list)
    # Weather and light models acting on the sensors (`environment { fog visibility 150 m }`).
    environment: list[ClausePlan] = Field(default_factory=list)
    # Their changes during the run (`at 10 s fog visibility 20 m`): steps armed at time 0 whose
    # clause replaces the model's settings from then on.
    environment_steps: list[TriggerPlan] = Field(default_factory=list)
    # Scenario variables (`variables { phase = 0 }`) and the steps that set them (`at 3 s set
    # phase 1`: a clause `set` named after the variable, its setting `value`).
    variables: list[VariablePlan] = Field(default_factory=list)
    variable_steps: list[TriggerPlan] = Field(default_factory=list)
    # `end when C [delayed D]`: the run ends where this start fires (no clause), at the
    # latest at `duration_s` (OpenSCENARIO's storyboard stop trigger).
    end: TriggerPlan | None = None

    def road(self, name: str) -> RoadPlan:
        return next(r for r in self.roads if r.name == name)

    def actors(self) -> list[ActorPlan]:
        return [self.ego, *self.agents]

    def nominal_params(self) -> dict[str, float]:
        return {p.name: p.default for p in self.params}

    # What a fault-free run does not read: the fault schedule, the parameter declarations
    # and the sweep (they make RunSpecs), the assumptions (they reject them).
    NOT_READ_WITHOUT_FAULTS: ClassVar[frozenset[str]] = frozenset({"faults", "params", "assumptions", "sweep"})

    def fault_only_params(self) -> frozenset[str]:
        """The parameters only the fault schedule reads (`drop_rate` in `drop lidar rate
        drop_rate`): runs that differ only in them have the same fault-free twin, and
        sweeps give them the same seeds (paired runs, `sweep.py`). (A walk of the plan,
        about 0.1 ms: nothing to cache beside a run.)"""
        read = set()
        for name in type(self).model_fields:
            if name not in self.NOT_READ_WITHOUT_FAULTS:
                read |= _params_in(getattr(self, name))
        return frozenset(_params_in(self.faults) - read)

    # Names a plan keeps for display only: how the scenario's path, or an imported map's,
    # was spelled. Its identity (store plan hashes, RunSpec keys) is everything else, so the
    # same file reached by another path is the same plan; imported maps are embedded
    # (`xodr_text`) and includes are inlined, so their content is part of it.
    DISPLAY_ONLY: ClassVar[dict] = {"source_file": True, "roads": {"__all__": {"xodr_file"}},
                                    "faults": {"__all__": {"source"}}}

    def identity(self) -> dict:
        """The plan's content as JSON-ready data, without display-only names."""
        return self.model_dump(mode="json", exclude=self.DISPLAY_ONLY)


def _params_in(value) -> set[str]:
    """Names of the parameters a plan value reads (any nesting of models, Expr trees
    included, lists and dicts)."""
    if isinstance(value, Param):
        return {value.name}
    if isinstance(value, BaseModel):
        return set().union(*(_params_in(getattr(value, f)) for f in type(value).model_fields))
    if isinstance(value, (list, tuple)):
        return set().union(*(_params_in(v) for v in value))
    if isinstance(value, dict):
        return set().union(*(_params_in(v) for v in value.values()))
    return set()


class ConcreteFault(_Model):
    """A fault with every value resolved for one run; `index` is its place in the schedule."""

    index: int
    kind: str
    target: str
    start_s: float
    end_s: float | None
    settings: dict[str, float | str | list[float]] = Field(default_factory=dict)
    seed: int
    # The start that opens the window (parameters substituted); the times then count from it.
    opens: TriggerPlan | None = None


class RunSpec(_Model):
    """Everything one run needs: same RunSpec, same trace, bit for bit."""

    plan: ScenarioPlan
    params: dict[str, float]
    seed: int
    faults: list[ConcreteFault]
    run_id: str = ""
    cell: dict[str, float] = Field(default_factory=dict)  # the sweep cell (grid values)
    repeat_index: int = 0

    def key(self) -> str:
        """Content hash: the identity of a run for caches and result stores (with the
        fingerprint of the code that runs it: a new version or new stack data is a new key)."""
        payload = self.model_dump(mode="json", exclude={"run_id", "plan"})
        payload["plan"] = self.plan.identity()
        payload["code"] = code_fingerprint()
        data = json.dumps(payload, sort_keys=True, separators=(",", ":")).encode()
        return hashlib.sha256(data).hexdigest()[:20]


def resolve_setting(value: SettingValue, params: dict[str, float]) -> float | str | list[float]:
    if isinstance(value, str):
        return value
    if isinstance(value, list):
        return [eval_param_expr(v, params) for v in value]
    return eval_param_expr(value, params)


def resolve_settings(settings: dict[str, SettingValue], params: dict[str, float]) -> dict:
    return {k: resolve_setting(v, params) for k, v in settings.items()}


def num(value: float) -> Num:
    return Num(value=float(value))


def plan_json_schema() -> dict:
    schema = ScenarioPlan.model_json_schema()
    schema["$id"] = f"https://addt-dsl.dev/schema/plan-v{SCHEMA_VERSION}.json"
    schema["title"] = "addt-dsl ScenarioPlan"
    return schema
