"""What the rules share: the `Context` they read and fill, and the checks every rule uses
(settings against `ParamSpec`s, ranges with interval arithmetic over parameter ranges,
constants, messages).
"""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass, field, fields

from addt_dsl import expr as E
from addt_dsl import plan as P
from addt_dsl import units
from addt_dsl.compiler import ast
from addt_dsl.compiler.exprs import ExprLowering, Scope, value_range
from addt_dsl.diagnostics import DiagnosticSink, Span
from addt_dsl.limits import DEFAULT, MAX_ABS_NUMBER, Limits
from addt_dsl.registry import SIGNALS, STACKS, ParamSpec

INT_EPS = 1e-9


@dataclass
class RoadInfo:
    """What the compiler knows of a road's shape, for placement and lane checks."""

    length_m: float
    lane_ids: tuple[int, ...]  # lanes at s = 0 (inline roads: everywhere)
    lane_width_m: dict[int, float]  # narrowest width of each lane along the road
    network: object = None  # the imported file's RoadNetwork (routes are checked on it); None inline
    road_id: str = ""  # the imported road's id in `network`


@dataclass
class Context:
    """The scenario being checked and what the rules have derived from it so far.

    Rules read it and return their product (a dataclass whose fields are fields of the
    context), which `absorb` stores; diagnostics go to `sink`. `used_params` is filled by
    every expression lowering (through the scope) and read by the last rule."""

    scenario: ast.Scenario
    sink: DiagnosticSink
    base_dir: str
    source_file: str
    roads_ast: dict[str, ast.RoadDecl] = field(default_factory=dict)
    params_ast: dict[str, ast.ParamDecl] = field(default_factory=dict)
    actors_ast: dict[str, ast.ActorDecl] = field(default_factory=dict)
    # Named steps as `actor.label` (rules/names.py), for `started(...)`/`ended(...)`.
    step_names: dict[str, Span] = field(default_factory=dict)
    header: dict = field(default_factory=dict)
    roads: list[P.RoadPlan] = field(default_factory=list)
    road_info: dict[str, RoadInfo] = field(default_factory=dict)
    params: list[P.ParamPlan] = field(default_factory=list)
    param_dims: dict[str, units.Dim] = field(default_factory=dict)
    param_ranges: dict[str, tuple[float, float]] = field(default_factory=dict)
    assumptions: list[P.AssumptionPlan] = field(default_factory=list)
    actors: dict[str, P.ActorPlan] = field(default_factory=dict)
    faults: list[P.FaultPlan] = field(default_factory=list)
    environment: list[P.ClausePlan] = field(default_factory=list)
    environment_steps: list[P.TriggerPlan] = field(default_factory=list)
    variables: list[P.VariablePlan] = field(default_factory=list)
    variable_steps: list[P.TriggerPlan] = field(default_factory=list)
    oracles: list[P.OraclePlan] = field(default_factory=list)
    sweep: P.SweepPlan = field(default_factory=P.SweepPlan)
    signals: list[P.SignalPlan] = field(default_factory=list)
    controllers: list[P.ControllerPlan] = field(default_factory=list)
    light_steps: list[P.TriggerPlan] = field(default_factory=list)
    end: P.TriggerPlan | None = None
    used_params: set[str] = field(default_factory=set)
    read_file: object = None  # callable(path str, span) -> (display, text) | None
    sources: dict[str, str] = field(default_factory=dict)
    lines: dict[str, list[str]] = field(default_factory=dict)  # sources split, on demand
    xodr_networks: dict = field(default_factory=dict)  # parsed imports by file
    limits: Limits = DEFAULT  # input limits and cost thresholds (addt_dsl/limits.py)
    _scopes: dict = field(default_factory=dict)

    def absorb(self, product) -> None:
        for f in fields(product):
            setattr(self, f.name, getattr(product, f.name))

    def defs(self, cls):
        return [d for d in self.scenario.definitions if isinstance(d, cls)]

    def blocks(self, kind: str):
        return [d for d in self.scenario.definitions if isinstance(d, ast.Block) and d.kind == kind]

    def scope(self, signals: bool) -> Scope:
        # Built once per kind after the parameters are known (scopes are read-only).
        key = (signals, len(self.param_dims), len(self.actors_ast))
        cached = self._scopes.get(key)
        if cached is not None:
            return cached
        nodes = set()
        for clause in self._ego_stack_clauses():
            cls = STACKS.get(clause)
            if cls is not None:
                nodes |= set(cls.nodes)
        scope = Scope(dict(self.param_dims), set(self.actors_ast), nodes | {"e2e"}, signals, self.used_params,
                      steps=set(self.step_names), lights=self.light_names(), variables=self.variable_names())
        self._scopes[key] = scope
        return scope

    def variable_names(self) -> set[str]:
        """Variables declared in `variables { }` (formulas read them: `var(phase)`)."""
        return {d.name for b in self.blocks("variables") for d in b.items if isinstance(d, ast.VarDef)}

    def light_names(self) -> set[str]:
        """Controllers declared in `lights { }` (formulas refer to them: `light(west)`)."""
        return {d.name for b in self.blocks("lights") for d in b.items
                if isinstance(d, ast.LightDef) and d.kind == "controller"}

    def _ego_stack_clauses(self):
        ego = self.actors_ast.get("ego")
        names = [c.name for c in ego.clauses if c.keyword == "stack"] if ego else []
        return names or ["bev"]

    def lowering(self, signals: bool = False) -> ExprLowering:
        return ExprLowering(self.sink, self.scope(signals))

    @property
    def duration(self) -> float | None:
        return self.header.get("duration")


def suggest(name: str, options) -> tuple[str, ...]:
    close = difflib.get_close_matches(name, list(options), n=1)
    return (f"did you mean '{close[0]}'?",) if close else ()


def const_value(expr) -> float | None:
    try:
        return E.eval_param_expr(expr, {})
    except (E.UnboundParameter, TypeError, ValueError, OverflowError):
        return None


def fmt(value, dim, unit: str | None = None) -> str:
    """An SI value for a message: in `unit` when the source used one (`20 %`, `72 km/h`),
    else in the dimension's canonical unit."""
    if value is None:
        return "…"
    if unit is not None and unit in units.UNITS:
        return f"{value / units.UNITS[unit].factor:.6g} {unit}"
    canonical = units.CANONICAL_UNIT.get(dim or units.DIMENSIONLESS)
    return f"{value:.6g} {canonical}" if canonical else f"{value:.6g}"


def range_text(lo, hi, dim) -> str:
    return f"[{fmt(lo, dim)}, {fmt(hi, dim)}]"


def check_range(ctx: Context, expr, spec_low, spec_high, dim, what: str, span: Span,
                integer: bool = False, code: str = "E0301", unit: str | None = None) -> bool:
    """Check a value against [spec_low, spec_high]; a parameter-dependent value is checked
    over its parameters' ranges (interval arithmetic). False after reporting."""
    const = const_value(expr)
    if const is not None:
        if not math.isfinite(const):
            ctx.sink.error("E0204", f"{what} is not a finite number", span)
            return False
        if integer and abs(const - round(const)) > INT_EPS:
            ctx.sink.error("E0204", f"{what} must be a whole number", span)
            return False
        if abs(const) > MAX_ABS_NUMBER and (spec_low is None or spec_high is None):  # an open-ended setting
            ctx.sink.error(code, f"{what} = {fmt(const, dim)} is beyond ±{MAX_ABS_NUMBER:g} (SI units)", span,
                           "no quantity of a driving scenario is this large (docs/limits.md)")
            return False
        if (spec_low is not None and const < spec_low) or (spec_high is not None and const > spec_high):
            shown = f"{fmt(const, dim, unit)} = {fmt(const, dim)}" if unit in ("%", "km/h", "mph", "ms") \
                else fmt(const, dim)
            ctx.sink.error(code, f"{what} = {shown} is outside {range_text(spec_low, spec_high, dim)}", span)
            return False
        return True
    got = value_range(expr, ctx.param_ranges)
    if got is None:
        return True
    lo, hi = got
    if (spec_low is not None and lo < spec_low - INT_EPS) or (spec_high is not None and hi > spec_high + INT_EPS):
        used = ", ".join(sorted(E.params_used(expr)))
        ctx.sink.error(code, f"{what} can be outside {range_text(spec_low, spec_high, dim)}", span,
                       f"over the ranges of {used} it spans {range_text(lo, hi, dim)}",
                       "narrow the parameter range, or add an `assume` that excludes those values")
        return False
    return True


def check_settings(ctx: Context, settings: tuple[ast.Setting, ...], specs, what: str, span: Span,
                   signals: bool = False, skip_required: bool = False) -> dict[str, P.SettingValue]:
    """Check `key value` pairs against ParamSpecs; return lowered values (SI)."""
    specs = {s.name: s for s in specs}
    out: dict[str, P.SettingValue] = {}
    seen: dict[str, ast.Setting] = {}
    low = ctx.lowering(signals)
    for st in settings:
        spec = specs.get(st.key)
        if spec is None:
            ctx.sink.error("E0104", f"{what} has no setting '{st.key}'", st.key_span,
                           *suggest(st.key, specs),
                           f"settings of {what}: {', '.join(sorted(specs)) or '(none)'}")
            continue
        if st.key in seen:
            ctx.sink.error("E0102", f"setting '{st.key}' given twice", st.key_span,
                           f"first given at {seen[st.key].key_span}")
            continue
        seen[st.key] = st
        value = lower_setting(ctx, low, st, spec, what)
        if value is not None:
            out[st.key] = value
    if not skip_required:
        for spec in specs.values():
            if spec.required and spec.name not in seen:
                ctx.sink.error("E0105", f"{what} needs setting '{spec.name}'", span,
                               *([f"{spec.name}: {spec.doc}"] if spec.doc else []))
    return out


def lower_setting(ctx: Context, low: ExprLowering, st: ast.Setting, spec: ParamSpec, what: str):
    v = st.value
    if spec.kind == "string":
        if not isinstance(v, ast.Str):
            ctx.sink.error("E0204", f"'{st.key}' takes a string in quotes", v.span)
            return None
        return v.value
    if spec.kind in ("word", "name"):
        if not (isinstance(v, ast.Ref) and len(v.parts) == 1):
            ctx.sink.error("E0204", f"'{st.key}' takes a name", v.span,
                           *([f"one of: {', '.join(spec.choices)}"] if spec.choices else []))
            return None
        word = v.parts[0]
        if spec.choices and word not in spec.choices:
            ctx.sink.error("E0204", f"'{word}' is not a valid {st.key}", v.span, *suggest(word, spec.choices),
                           f"one of: {', '.join(spec.choices)}")
            return None
        return word
    if spec.kind == "list":
        return _lower_list_setting(ctx, low, st, spec, what)
    if isinstance(v, ast.ListExpr):
        ctx.sink.error("E0204", f"'{st.key}' takes one value, not a list", v.span)
        return None
    if isinstance(v, ast.Str):
        ctx.sink.error("E0204", f"'{st.key}' takes a number, not a string", v.span)
        return None
    want = spec.dim if spec.dim is not None else units.DIMENSIONLESS
    if spec.live and not low.scope.allow_signals:
        low = ctx.lowering(signals=True)
    expr = low.lower_value(v, want, f"'{st.key}' of {what}")
    if expr is None:
        return None
    if not check_range(ctx, expr, spec.low, spec.high, spec.dim, f"'{st.key}'", v.span,
                       integer=spec.kind == "int", unit=source_unit(v)):
        return None
    return expr


def _lower_list_setting(ctx: Context, low: ExprLowering, st: ast.Setting, spec: ParamSpec, what: str):
    """A list setting (`times [0, 4, 8] s`): items may use parameters; each is checked
    against the setting's dimension and range."""
    v = st.value
    if not isinstance(v, ast.ListExpr):
        ctx.sink.error("E0204", f"'{st.key}' takes a list, e.g. `{st.key} [1, 2, 3] ...`", v.span)
        return None
    if not v.items:
        ctx.sink.error("E0204", f"'{st.key}' is empty", v.span)
        return None
    out = []
    for item in v.items:
        item = list_item(ctx, v, item, f"'{st.key}'")
        if item is None:
            return None
        expr = low.lower_value(item, spec.dim if spec.dim is not None else units.DIMENSIONLESS,
                               f"an item of '{st.key}' of {what}")
        if expr is None:
            return None
        if not check_range(ctx, expr, spec.low, spec.high, spec.dim, f"'{st.key}'", item.span,
                           unit=source_unit(item)):
            return None
        out.append(expr)
    return out


def list_item(ctx: Context, lst: ast.ListExpr, item, label: str):
    """A list item as a number with the list's unit (`[1, 2, 3] m`), or None with E0202 (units
    on the list and the item) or E0204 (not a number)."""
    if lst.unit is not None and isinstance(item, ast.Number) and item.unit is None:
        return ast.Number(item.span, item.value, lst.unit)
    if lst.unit is not None and isinstance(item, ast.Number):
        ctx.sink.error("E0202", f"{label} has units on the list and on an item", item.span,
                       f"write `[1, 2, 3] {lst.unit}` or give each item its unit")
        return None
    if isinstance(item, (ast.Str, ast.ListExpr)):
        ctx.sink.error("E0204", f"{label} must list numbers", item.span)
        return None
    return item


def int_const(expr) -> int | None:
    v = const_value(expr)
    return int(round(v)) if v is not None and math.isfinite(v) else None


def lower_list(ctx: Context, node: ast.ListExpr, dim, what: str) -> list[float] | None:
    vals = []
    low = ExprLowering(ctx.sink, Scope({}, set(), set(), False, set()))
    for item in node.items:
        item = list_item(ctx, node, item, what)
        if item is None:
            return None
        e = low.lower_value(item, dim, what)
        if e is None:
            return None
        c = const_value(e)
        if c is None or not math.isfinite(c):
            ctx.sink.error("E0204", f"{what} must list finite constants", item.span)
            return None
        vals.append(c)
    if not vals:
        ctx.sink.error("E0204", f"{what} is empty", node.span)
        return None
    return vals


def check_time(ctx: Context, value, span: Span, what: str) -> bool:
    """A time must lie in [0, duration] (E0302 otherwise)."""
    dur = ctx.duration
    what = what if what.startswith("the") else f"the time of {what}"
    return check_range(ctx, value, 0.0, dur if isinstance(dur, float) else None, units.TIME, what, span,
                       code="E0302")


def check_trigger_condition(ctx: Context, condition, span: Span) -> bool:
    """A `when` condition is checked on the current state (E0204 otherwise): no temporal
    operators, and no signal whose value at an instant needs the run before it (`jerk`,
    `travelled`: `SignalFn.history`), which the check at an instant does not have."""
    ok = True
    if any(isinstance(n, (E.Temporal, E.Until)) for n in E.walk(condition)):
        ctx.sink.error("E0204", "a trigger condition is checked at each instant; it cannot use "
                       "always/eventually/until", span,
                       "write the condition on the current state, e.g. `when gap(ego, lead) < 20 m`")
        ok = False
    for name in sorted({n.name.split("(")[0] for n in E.walk(condition) if isinstance(n, E.Signal)}):
        if getattr(SIGNALS.get(name), "history", False):
            ctx.sink.error("E0204", f"`{name}` needs the run's past, which a trigger condition does not see: "
                           "it is checked on the current state", span, "use it in an oracle (`expect`)")
            ok = False
    return ok


MAX_STEP_REPEATS = 1_000_000  # `when C repeat N`


@dataclass(frozen=True)
class When:
    """A lowered `when [EDGE] C [for D] [delay D]` start (None: an error was reported)."""

    condition: E.Expr
    hold_s: E.Expr | None
    edge: str | None
    delay_s: E.Expr | None
    repeat: int | None = None


def lower_when(ctx: Context, start: ast.StepStart) -> When | None:
    """The `when` start of a step, for actors' and lights' steps alike."""
    ok = True
    condition = ctx.lowering(signals=True).lower_formula(start.value, "a trigger condition")
    if condition is None or not check_trigger_condition(ctx, condition, start.value.span):
        ok = False
    low = ctx.lowering()
    hold = delay = None
    if start.hold is not None:
        hold = low.lower_value(start.hold, units.TIME, "how long the condition must hold")
        if hold is None or not check_time(ctx, hold, start.hold.span, "the hold of `when ... for`"):
            ok = False
    if start.delay is not None:
        delay = low.lower_value(start.delay, units.TIME, "the delay of `when ... delayed`")
        if delay is None or not check_time(ctx, delay, start.delay.span, "the delay of `when ... delayed`"):
            ok = False
    repeat = None
    if start.repeat is not None:
        value = low.lower_value(start.repeat, units.DIMENSIONLESS, "how many times the step fires")
        count = const_value(value) if value is not None else None
        if count is None or count != int(count) or not 1 <= count <= MAX_STEP_REPEATS:
            ctx.sink.error("E0204", f"`repeat` takes a whole number from 1 to {MAX_STEP_REPEATS}", start.repeat.span)
            ok = False
        else:
            repeat = int(count)
    return When(condition, hold, start.edge, delay, repeat) if ok else None


@dataclass(frozen=True)
class Starts:
    """A step's lowered starts: `TriggerPlan` fields, the `when` (None without one) and the
    start nodes by kind; `ok` False after an error was reported."""

    ok: bool
    fields: dict
    when: When | None
    nodes: dict


def lower_starts(ctx: Context, starts: tuple[ast.StepStart, ...]) -> Starts:
    """`at T`, `after T`, `when ...` of an actor's step, a light step or `end`: each kind at
    most once (E0102), times as times (the one lowering of a step's start)."""
    nodes: dict[str, ast.StepStart] = {}
    ok = True
    for st in starts:
        if st.kind in nodes:
            ctx.sink.error("E0102", f"`{st.kind}` given twice in one step", st.span)
            ok = False
        nodes[st.kind] = st
    fields: dict = {}
    low = ctx.lowering()
    for kind, key in (("at", "at_s"), ("after", "after_s")):
        if kind in nodes:
            value = low.lower_value(nodes[kind].value, units.TIME, f"the time of `{kind}`")
            if value is None or not check_time(ctx, value, nodes[kind].value.span, f"`{kind}`"):
                ok = False
            fields[key] = value
    when = lower_when(ctx, nodes["when"]) if "when" in nodes else None
    if "when" in nodes and when is None:
        ok = False
    if when is not None:
        fields.update(when_fields(when))
    return Starts(ok, fields, when, nodes)


def validate_settings(ctx: Context, cls, vals: dict, settings: tuple, span: Span) -> bool:
    """A registered class's own checks across its settings (`validate(values) -> [(setting,
    message[, code])]`, e.g. a speed profile's times and speeds), on the settings that are
    constants (a setting that is not one is passed as None)."""
    validate = getattr(cls, "validate", None)
    if validate is None:
        return True
    consts = {}
    for key, value in vals.items():
        if isinstance(value, list):
            items = [const_value(v) for v in value]
            consts[key] = None if any(i is None for i in items) else items
        else:
            consts[key] = value if isinstance(value, str) else const_value(value)
    problems = validate(consts)
    for key, message, *code in problems:  # E0204 unless the class gives a code
        at = next((st.value.span for st in settings if st.key == key), span)
        ctx.sink.error(code[0] if code else "E0204", message, at)
    return not problems


def when_fields(when: When) -> dict:
    """The `TriggerPlan` fields of a lowered `when` start."""
    return {"condition": when.condition, "hold_s": when.hold_s, "edge": when.edge, "delay_s": when.delay_s,
            "repeat": when.repeat}


def text_of(ctx: Context, span: Span) -> str:
    """The source text of a one-line span (oracle and constraint texts for reports)."""
    lines = ctx.lines.get(span.file)
    if lines is None:
        lines = ctx.lines[span.file] = ctx.sources.get(span.file, "").splitlines()
    if span.line - 1 < len(lines):
        line = lines[span.line - 1]
        end = span.end_col - 1 if span.end_line == span.line else len(line)
        # Parentheses are not tokens of the tree, so a span stops before a statement's
        # closing brackets: take them back (only brackets and blanks may follow).
        rest = line[end:].split("#", 1)[0]
        if rest.strip() and set(rest.strip()) <= set(")]"):
            end += len(rest.rstrip())
        return line[span.col - 1:end].strip()
    return ""


def source_unit(node) -> str | None:
    return node.unit if isinstance(node, ast.Number) else None
