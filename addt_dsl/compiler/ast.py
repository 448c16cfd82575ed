"""The .addt abstract syntax tree: frozen dataclasses, every node with its source span.

Built from lark's parse tree by `compiler.parser`; read by `compiler.check` and
`compiler.lower`. Nothing here knows about units or registries: that is checking.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from addt_dsl.diagnostics import Span


@dataclass(frozen=True, slots=True)
class Node:
    span: Span


# ---------------------------------------------------------------- expressions

@dataclass(frozen=True, slots=True)
class Number(Node):
    value: float
    unit: str | None = None


@dataclass(frozen=True, slots=True)
class Str(Node):
    value: str


@dataclass(frozen=True, slots=True)
class Bool(Node):
    value: bool


@dataclass(frozen=True, slots=True)
class Ref(Node):
    """A dotted name: a parameter (`gap`), an actor field (`ego.speed`) or a word (`weights`)."""

    parts: tuple[str, ...]

    @property
    def dotted(self) -> str:
        return ".".join(self.parts)


@dataclass(frozen=True, slots=True)
class CallExpr(Node):
    fn: str
    args: tuple[Expression, ...]


@dataclass(frozen=True, slots=True)
class UnaryExpr(Node):
    op: str  # "neg" | "not"
    arg: Expression


@dataclass(frozen=True, slots=True)
class BinaryExpr(Node):
    op: str
    left: Expression
    right: Expression


@dataclass(frozen=True, slots=True)
class Window(Node):
    """A time window of a temporal operator; `hi` None means to the end of the trace."""

    lo: Expression | None
    hi: Expression | None


@dataclass(frozen=True, slots=True)
class TemporalExpr(Node):
    op: str  # "always" | "eventually"
    window: Window | None
    arg: Expression


@dataclass(frozen=True, slots=True)
class UntilExpr(Node):
    window: Window | None
    left: Expression
    right: Expression


@dataclass(frozen=True, slots=True)
class ListExpr(Node):
    items: tuple[Expression, ...]
    unit: str | None = None


Expression = (Number | Str | Bool | Ref | CallExpr | UnaryExpr | BinaryExpr | TemporalExpr
              | UntilExpr | ListExpr)


# ---------------------------------------------------------------- statements

@dataclass(frozen=True, slots=True)
class Setting(Node):
    key: str
    key_span: Span
    value: Expression


@dataclass(frozen=True, slots=True)
class Include(Node):
    path: str


@dataclass(frozen=True, slots=True)
class RoadItem(Node):
    kind: str  # geometry primitive (`line`, `arc`, ...) or `lanes`
    settings: tuple[Setting, ...]


@dataclass(frozen=True, slots=True)
class RoadDecl(Node):
    name: str
    items: tuple[RoadItem, ...] = ()
    import_path: str | None = None
    import_settings: tuple[Setting, ...] = ()


@dataclass(frozen=True, slots=True)
class ParamDecl(Node):
    name: str
    default: Expression
    domain: Expression | None
    settings: tuple[Setting, ...]


@dataclass(frozen=True, slots=True)
class AssumeDecl(Node):
    """`assume [name:] expr` or `keep [name:] expr`: a constraint on parameter samples."""

    expr: Expression
    label: str | None = None


@dataclass(frozen=True, slots=True)
class Clause(Node):
    """`behavior cruise speed 10 m/s`, `sensor lidar rate 10 Hz`, `stack bev`, `goal ...`."""

    keyword: str  # behavior | sensor | stack | goal | node
    name: str
    name_span: Span
    settings: tuple[Setting, ...]
    block: tuple[Setting, ...] = ()


@dataclass(frozen=True, slots=True)
class StepStart(Node):
    kind: str  # at | after | when
    value: Expression
    hold: Expression | None = None  # `when C for D`: C must have held for D
    edge: str | None = None  # `when rising C`: rising | falling | changing
    delay: Expression | None = None  # `when C delayed D`: fires D after C (its edge) fired
    repeat: Expression | None = None  # `when C repeat N`: fires up to N times


@dataclass(frozen=True, slots=True)
class EndWhen(Node):
    """`end when C [delayed D]` (or `end at T`, `end after D`): when the run ends."""

    starts: tuple[StepStart, ...]


@dataclass(frozen=True, slots=True)
class Step(Node):
    """`at 5 s`, `after 2 s`, `when <cond>` (any combination), then a clause or a group."""

    starts: tuple[StepStart, ...]
    action: Clause | Group
    label: str | None = None  # `brake_hard: at 3 s ...`
    label_span: Span | None = None


@dataclass(frozen=True, slots=True)
class Group(Node):
    mode: str  # sequence | parallel
    items: tuple[Clause | Step | Group, ...]
    label: str | None = None  # `swerve: sequence { ... }`
    label_span: Span | None = None


@dataclass(frozen=True, slots=True)
class Placement(Node):
    """`ahead of lead 20 m`, `behind ego 10 m`, `lane of ego`, `lane left of ego`."""

    kind: str  # ahead | behind | lane_of | lane_left | lane_right
    actor: str
    actor_span: Span
    distance: Expression | None = None


@dataclass(frozen=True, slots=True)
class Route(Node):
    """`route 1 -> left -> 3`: road ids and turns, each with its span."""

    stops: tuple[str, ...]
    stop_spans: tuple[Span, ...]


@dataclass(frozen=True, slots=True)
class ActorDecl(Node):
    name: str
    is_ego: bool
    vehicle: str
    vehicle_span: Span
    settings: tuple[Setting, ...]
    clauses: tuple[Clause, ...] = ()
    steps: tuple[Step | Group, ...] = ()
    block_settings: tuple[Setting, ...] = ()
    placements: tuple[Placement, ...] = ()
    route: Route | None = None


@dataclass(frozen=True, slots=True)
class LightDef(Node):
    """A line of `lights { }`: `signal NAME settings` or `controller NAME settings`."""

    kind: str
    kind_span: Span
    name: str
    name_span: Span
    settings: tuple[Setting, ...]


@dataclass(frozen=True, slots=True)
class Timing(Node):
    kind: str  # at | during | from | when
    start: Expression  # `when`: the condition
    end: Expression | None = None
    length: Expression | None = None  # `at T for D`, `when C for D`
    edge: str | None = None  # `when rising C`: rising | falling | changing
    delay: Expression | None = None  # `when C delayed D`


@dataclass(frozen=True, slots=True)
class FaultDecl(Node):
    kind: str
    kind_span: Span
    target: tuple[str, ...]
    target_span: Span
    timing: Timing | None
    settings: tuple[Setting, ...]


@dataclass(frozen=True, slots=True)
class Builtin(Node):
    """A built-in oracle: `no collision [with X]`, `stay in lane`, `reach goal [within T]`,
    `min SIGNAL [to|of X] V`, `max SIGNAL [of X] V`."""

    kind: str  # no | stay_in_lane | reach_goal | min | max
    word: str | None = None  # `collision`, or the signal of a bound
    word_span: Span | None = None
    actor: str | None = None
    actor_span: Span | None = None
    value: Expression | None = None
    settings: tuple[Setting, ...] = ()


@dataclass(frozen=True, slots=True)
class OracleDecl(Node):
    severity: str  # hard | warn
    label: str | None
    formula: Expression | None = None
    builtin: Builtin | None = None


@dataclass(frozen=True, slots=True)
class SweepItem(Node):
    kind: str  # grid | cases | random | halton | lhs | repeat | seed
    name: str | None
    value: Expression
    settings: tuple[Setting, ...] = ()


@dataclass(frozen=True, slots=True)
class EnvItem(Node):
    """`fog visibility 150 m` in an `environment { }` block."""

    name: str
    name_span: Span
    settings: tuple[Setting, ...] = ()


@dataclass(frozen=True, slots=True)
class EnvStep(Node):
    """`at 10 s fog visibility 20 m`: a change of the conditions during the run."""

    starts: tuple[StepStart, ...]
    item: EnvItem


@dataclass(frozen=True, slots=True)
class VarDef(Node):
    """`phase = 0` in a `variables { }` block: a scenario variable and its first value."""

    name: str
    name_span: Span
    value: Expression


@dataclass(frozen=True, slots=True)
class VarStep(Node):
    """`at 3 s set phase 1`: a step that sets a scenario variable."""

    starts: tuple[StepStart, ...]
    name: str
    name_span: Span
    value: Expression


@dataclass(frozen=True, slots=True)
class Block(Node):
    """`faults { }`, `expect { }`, `sweep { }`, `environment { }` — kept as blocks for span reporting."""

    kind: str
    items: tuple = ()


Definition = RoadDecl | ParamDecl | AssumeDecl | ActorDecl | Block | EndWhen


@dataclass(frozen=True, slots=True)
class Scenario(Node):
    name: str
    settings: tuple[Setting, ...]
    definitions: tuple[Definition, ...]
    includes: tuple[Include, ...] = ()


@dataclass(frozen=True, slots=True)
class SourceFile(Node):
    path: str
    includes: tuple[Include, ...] = ()
    scenarios: tuple[Scenario, ...] = ()
    definitions: tuple[Definition, ...] = field(default_factory=tuple)
