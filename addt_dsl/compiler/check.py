"""Semantic checks: small rules, run in order, each adding diagnostics and checked pieces.

Like sqlglot's optimizer rules, each rule is a plain function of the `Context`; `RULES`
fixes their order (names before uses). Rules never stop at the first error: a broken
statement is reported and skipped, the rest is still checked.
"""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass, field

from addt_dsl import expr as E
from addt_dsl import plan as P
from addt_dsl import units
from addt_dsl.compiler import ast
from addt_dsl.compiler.exprs import ExprLowering, Scope
from addt_dsl.diagnostics import DiagnosticSink, Span
from addt_dsl.registry import BEHAVIORS, FAULTS, GEOMETRIES, SENSORS, STACKS, ParamSpec

HEADER = {
    "description": ParamSpec("description", None, kind="string", doc="free text"),
    "duration": ParamSpec("duration", units.TIME, required=True, low=0.1, high=3600.0, doc="simulated time"),
    "step": ParamSpec("step", units.TIME, default=0.01, low=0.001, high=0.1, doc="physics step"),
    "seed": ParamSpec("seed", None, kind="int", default=0, low=0, high=2**31 - 1, doc="base seed"),
}

ACTOR_SETTINGS = (
    ParamSpec("on", None, kind="name", required=True, doc="road the actor starts on"),
    ParamSpec("lane", None, kind="int", required=True, low=-20, high=20, doc="lane id (OpenDRIVE)"),
    ParamSpec("at", units.LENGTH, required=True, low=0.0, doc="station along the road"),
    ParamSpec("speed", units.SPEED, default=0.0, low=0.0, high=100.0, doc="initial speed"),
    ParamSpec("goal", units.LENGTH, low=0.0, doc="station the ego must reach (ego only)"),
    ParamSpec("length", units.LENGTH, low=0.1, high=30.0, doc="body length"),
    ParamSpec("width", units.LENGTH, low=0.1, high=5.0, doc="body width"),
    ParamSpec("mass", units.MASS, default=1500.0, low=50.0, high=60000.0, doc="mass"),
    ParamSpec("wheelbase", units.LENGTH, default=2.7, low=0.5, high=10.0, doc="wheelbase"),
)

VEHICLE_KINDS = {"car": (4.6, 1.9), "truck": (12.0, 2.5), "pedestrian": (0.5, 0.5), "cyclist": (1.8, 0.6)}
DEFAULT_SENSOR = P.ClausePlan(keyword="sensor", name="lidar", settings={})
DEFAULT_STACK = P.ClausePlan(keyword="stack", name="bev", settings={})


@dataclass
class Context:
    scenario: ast.Scenario
    sink: DiagnosticSink
    base_dir: str
    source_file: str
    roads_ast: dict[str, ast.RoadDecl] = field(default_factory=dict)
    params_ast: dict[str, ast.ParamDecl] = field(default_factory=dict)
    actors_ast: dict[str, ast.ActorDecl] = field(default_factory=dict)
    header: dict = field(default_factory=dict)
    roads: list[P.RoadPlan] = field(default_factory=list)
    params: list[P.ParamPlan] = field(default_factory=list)
    param_dims: dict[str, units.Dim] = field(default_factory=dict)
    assumptions: list[P.AssumptionPlan] = field(default_factory=list)
    actors: dict[str, P.ActorPlan] = field(default_factory=dict)
    faults: list[P.FaultPlan] = field(default_factory=list)
    oracles: list[P.OraclePlan] = field(default_factory=list)
    sweep: P.SweepPlan = field(default_factory=P.SweepPlan)
    used_params: set[str] = field(default_factory=set)
    read_file: object = None  # callable(path str, span) -> (display, text) | None

    def defs(self, cls):
        return [d for d in self.scenario.definitions if isinstance(d, cls)]

    def blocks(self, kind: str):
        return [d for d in self.scenario.definitions if isinstance(d, ast.Block) and d.kind == kind]

    def scope(self, signals: bool) -> Scope:
        nodes = set()
        for clause in self._ego_stack_clauses():
            cls = STACKS.get(clause)
            if cls is not None:
                nodes |= set(cls.nodes)
        return Scope(dict(self.param_dims), set(self.actors_ast), nodes | {"e2e"}, signals, self.used_params)

    def _ego_stack_clauses(self):
        ego = self.actors_ast.get("ego")
        names = [c.name for c in ego.clauses if c.keyword == "stack"] if ego else []
        return names or ["bev"]

    def lowering(self, signals: bool = False) -> ExprLowering:
        return ExprLowering(self.sink, self.scope(signals))

    @property
    def duration(self) -> float | None:
        return self.header.get("duration")


def _suggest(name: str, options) -> tuple[str, ...]:
    close = difflib.get_close_matches(name, list(options), n=1)
    return (f"did you mean '{close[0]}'?",) if close else ()


def _const_value(expr) -> float | None:
    try:
        return E.eval_param_expr(expr, {})
    except (E.UnboundParameter, TypeError):
        return None


def check_settings(ctx: Context, settings: tuple[ast.Setting, ...], specs, what: str, span: Span,
                   signals: bool = False) -> dict[str, P.SettingValue]:
    """Check `key value` pairs against ParamSpecs; return lowered values (SI)."""
    specs = {s.name: s for s in specs}
    out: dict[str, P.SettingValue] = {}
    seen: dict[str, ast.Setting] = {}
    low = ctx.lowering(signals)
    for st in settings:
        spec = specs.get(st.key)
        if spec is None:
            ctx.sink.error("E0104", f"{what} has no setting '{st.key}'", st.key_span,
                           *_suggest(st.key, specs),
                           f"settings of {what}: {', '.join(sorted(specs)) or '(none)'}")
            continue
        if st.key in seen:
            ctx.sink.error("E0102", f"setting '{st.key}' given twice", st.key_span)
            continue
        seen[st.key] = st
        value = lower_setting(ctx, low, st, spec, what)
        if value is not None:
            out[st.key] = value
    for spec in specs.values():
        if spec.required and spec.name not in seen:
            ctx.sink.error("E0105", f"{what} needs setting '{spec.name}'", span,
                           f"{spec.name}: {spec.doc}" if spec.doc else "")
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
            ctx.sink.error("E0204", f"'{word}' is not a valid {st.key}", v.span, *_suggest(word, spec.choices),
                           f"one of: {', '.join(spec.choices)}")
            return None
        return word
    if isinstance(v, ast.ListExpr):
        ctx.sink.error("E0204", f"'{st.key}' takes one value, not a list", v.span)
        return None
    want = spec.dim if spec.dim is not None else units.DIMENSIONLESS
    expr = low.lower_value(v, want, f"'{st.key}' of {what}")
    if expr is None:
        return None
    const = _const_value(expr)
    if const is not None:
        if spec.kind == "int" and const != math.floor(const):
            ctx.sink.error("E0204", f"'{st.key}' must be a whole number", v.span)
            return None
        if (spec.low is not None and const < spec.low) or (spec.high is not None and const > spec.high):
            rng = f"[{_fmt(spec.low, spec.dim)}, {_fmt(spec.high, spec.dim)}]"
            ctx.sink.error("E0301", f"'{st.key}' = {_fmt(const, spec.dim)} is outside {rng}", v.span)
            return None
    return expr


def _fmt(value, dim) -> str:
    if value is None:
        return "…"
    return units.format_si(value, dim or units.DIMENSIONLESS)


# ---------------------------------------------------------------- rules

def rule_names(ctx: Context) -> None:
    """Collect declarations; duplicates are errors."""
    for kind, table in ((ast.RoadDecl, ctx.roads_ast), (ast.ParamDecl, ctx.params_ast),
                        (ast.ActorDecl, ctx.actors_ast)):
        for d in ctx.defs(kind):
            if d.name in table or (kind is ast.ActorDecl and d.name in ctx.params_ast):
                ctx.sink.error("E0102", f"'{d.name}' is defined twice", d.span,
                               f"first defined at {table[d.name].span}" if d.name in table else "")
                continue
            table[d.name] = d
    egos = [a for a in ctx.defs(ast.ActorDecl) if a.is_ego]
    if not egos:
        ctx.sink.error("E0103", f"scenario '{ctx.scenario.name}' has no ego vehicle", ctx.scenario.span,
                       "add e.g. `ego car on road1 lane -1 at 10 m speed 20 m/s`")
    if not ctx.roads_ast:
        ctx.sink.error("E0103", f"scenario '{ctx.scenario.name}' has no road", ctx.scenario.span)


def rule_header(ctx: Context) -> None:
    values = check_settings(ctx, ctx.scenario.settings, HEADER.values(), "the scenario", ctx.scenario.span)
    for key, spec in HEADER.items():
        v = values.get(key, spec.default)
        if isinstance(v, (E.Num, E.Binary, E.Unary, E.Call, E.Param)):
            const = _const_value(v)
            if const is None:
                ctx.sink.error("E0204", f"'{key}' must be a constant", ctx.scenario.span)
                continue
            v = const
        ctx.header[key] = v


def rule_params(ctx: Context) -> None:
    """Parameters: default, domain `in [lo, hi]` or choices, distribution."""
    # Dimensions first so parameters may reference earlier ones.
    for d in ctx.params_ast.values():
        low = ExprLowering(ctx.sink, Scope({}, set(), set(), False, set()))
        expr, ty = low.lower(d.default)
        if expr is None:
            continue
        if ty[0] != "num" or _const_value(expr) is None:
            ctx.sink.error("E0204", f"the default of '{d.name}' must be a constant number", d.default.span)
            continue
        dim = ty[1]
        ctx.param_dims[d.name] = dim
        default = _const_value(expr)
        lo = hi = None
        choices: list[float] = []
        if d.domain is not None:
            if not isinstance(d.domain, ast.ListExpr):
                ctx.sink.error("E0204", f"the domain of '{d.name}' is a list: `in [low, high]`", d.domain.span)
                continue
            vals = _lower_list(ctx, d.domain, dim, f"the domain of '{d.name}'")
            if vals is None:
                continue
            lo, hi = (vals[0], vals[1]) if len(vals) == 2 else (min(vals), max(vals))
            if len(vals) != 2:
                choices = vals
            if lo > hi:
                ctx.sink.error("E0303", f"the range of '{d.name}' is inverted", d.domain.span)
                continue
            if not (lo <= default <= hi) and not choices:
                ctx.sink.error("E0301", f"the default of '{d.name}' ({_fmt(default, dim)}) is outside its range "
                               f"[{_fmt(lo, dim)}, {_fmt(hi, dim)}]", d.default.span)
                continue
        opts = {s.key: s for s in d.settings}
        dist = "choice" if choices else "uniform"
        mean = sd = None
        for st in d.settings:
            if st.key == "dist":
                if isinstance(st.value, ast.Ref) and st.value.dotted in ("uniform", "normal", "choice"):
                    dist = st.value.dotted
                else:
                    ctx.sink.error("E0204", "dist is one of uniform, normal, choice", st.value.span)
            elif st.key == "sd":
                sd_expr = low.lower_value(st.value, dim, f"'sd' of '{d.name}'")
                sd = _const_value(sd_expr) if sd_expr is not None else None
            elif st.key == "mean":
                m_expr = low.lower_value(st.value, dim, f"'mean' of '{d.name}'")
                mean = _const_value(m_expr) if m_expr is not None else None
            else:
                ctx.sink.error("E0104", f"parameter has no setting '{st.key}'", st.key_span,
                               "settings of a parameter: dist, mean, sd")
        if dist == "normal" and "sd" not in opts:
            ctx.sink.error("E0105", f"normal parameter '{d.name}' needs 'sd'", d.span)
        if dist == "choice" and not choices:
            ctx.sink.error("E0204", f"choice parameter '{d.name}' needs `in [a, b, c, ...]`", d.span)
        ctx.params.append(P.ParamPlan(name=d.name, dimension=units.dim_name(dim), default=default,
                                      low=lo, high=hi, distribution=dist, mean=mean, sd=sd,
                                      choices=choices))


def _lower_list(ctx: Context, node: ast.ListExpr, dim, what: str) -> list[float] | None:
    vals = []
    low = ExprLowering(ctx.sink, Scope({}, set(), set(), False, set()))
    for item in node.items:
        if node.unit is not None and isinstance(item, ast.Number) and item.unit is None:
            item = ast.Number(item.span, item.value, node.unit)
        e = low.lower_value(item, dim, what)
        if e is None:
            return None
        c = _const_value(e)
        if c is None:
            ctx.sink.error("E0204", f"{what} must list constants", item.span)
            return None
        vals.append(c)
    if not vals:
        ctx.sink.error("E0204", f"{what} is empty", node.span)
        return None
    return vals


def rule_roads(ctx: Context) -> None:
    for d in ctx.roads_ast.values():
        if d.import_path is not None:
            _import_road(ctx, d)
            continue
        segments, lanes, broken = [], None, False
        for item in d.items:
            cls = GEOMETRIES.get(item.kind)
            if cls is None:
                broken = True
                ctx.sink.error("E0106", f"unknown road element '{item.kind}'", item.span,
                               *_suggest(item.kind, GEOMETRIES.names()),
                               f"road elements: {', '.join(GEOMETRIES.names())}")
                continue
            vals = check_settings(ctx, item.settings, cls.params, f"'{item.kind}'", item.span)
            consts = {k: _const_value(v) if not isinstance(v, str) else v for k, v in vals.items()}
            if any(v is None for v in consts.values()):
                ctx.sink.error("E0204", "road geometry must use constants, not parameters", item.span)
                continue
            spec = {p.name: p.default for p in cls.params}
            spec.update(consts)
            if item.kind == "lanes":
                if lanes is not None:
                    ctx.sink.error("E0102", "lanes given twice", item.span)
                lanes = spec
                continue
            if spec.get("length") is None:
                continue
            if item.kind == "line":
                segments.append(P.SegmentPlan(kind="line", length_m=spec["length"]))
            elif item.kind == "arc":
                segments.append(P.SegmentPlan(kind="arc", length_m=spec["length"],
                                              curvature_per_m=spec["curvature"]))
            elif item.kind == "spiral":
                segments.append(P.SegmentPlan(kind="spiral", length_m=spec["length"],
                                              curv_start_per_m=spec["from"], curv_end_per_m=spec["to"]))
            else:
                segments.append(P.SegmentPlan(kind="param_poly3", length_m=spec["length"], coefficients=[
                    spec[k] for k in ("au", "bu", "cu", "du", "av", "bv", "cv", "dv")]))
        if not segments:
            if broken:
                continue
            ctx.sink.error("E0103", f"road '{d.name}' has no geometry", d.span, "add e.g. `line length 500 m`")
            continue
        lanes = lanes or {p.name: p.default for p in GEOMETRIES.get("lanes").params}
        if int(lanes["left"]) + int(lanes["right"]) == 0:
            ctx.sink.error("E0204", f"road '{d.name}' has no lanes", d.span)
            continue
        ctx.roads.append(P.RoadPlan(name=d.name, source="inline", segments=segments,
                                    left_lanes=int(lanes["left"]), right_lanes=int(lanes["right"]),
                                    lane_width_m=lanes["width"], lane_offset_m=lanes["offset"]))


def _import_road(ctx: Context, d: ast.RoadDecl) -> None:
    specs = (ParamSpec("road", None, kind="int", doc="xodr road id to place actors on"),)
    vals = check_settings(ctx, d.import_settings, specs, "a road import", d.span)
    got = ctx.read_file(d.import_path, d.span) if ctx.read_file else None
    if got is None:
        return
    display, text = got
    from addt_dsl.compiler.xodr_check import check_xodr

    road_id = check_xodr(ctx, text, display, d.span, vals.get("road"))
    if road_id is None:
        return
    ctx.roads.append(P.RoadPlan(name=d.name, source="xodr", xodr_file=display, xodr_text=text,
                                xodr_road_id=road_id))


def rule_assumptions(ctx: Context) -> None:
    for d in ctx.defs(ast.AssumeDecl):
        low = ctx.lowering(signals=False)
        formula = low.lower_formula(d.expr, "an assumption")
        if formula is not None:
            ctx.assumptions.append(P.AssumptionPlan(text=_text_of(ctx, d.expr.span), expr=formula))


def rule_actors(ctx: Context) -> None:
    for d in ctx.actors_ast.values():
        if d.vehicle not in VEHICLE_KINDS:
            ctx.sink.error("E0106", f"unknown vehicle kind '{d.vehicle}'", d.vehicle_span,
                           *_suggest(d.vehicle, VEHICLE_KINDS), f"kinds: {', '.join(VEHICLE_KINDS)}")
            continue
        what = "the ego" if d.is_ego else f"agent '{d.name}'"
        vals = check_settings(ctx, d.settings + d.block_settings, ACTOR_SETTINGS, what, d.span)
        road = vals.get("on")
        if isinstance(road, str) and road not in ctx.roads_ast:
            span = next(s.value.span for s in d.settings if s.key == "on")
            ctx.sink.error("E0101", f"unknown road '{road}'", span, *_suggest(road, ctx.roads_ast))
            continue
        if "goal" in vals and not d.is_ego:
            ctx.sink.warning("W0002", "only the ego has a goal", d.span)
        behaviors, sensors, stack = [], [], None
        for c in d.clauses:
            plan = _check_clause(ctx, c, d)
            if plan is None:
                continue
            if c.keyword == "behavior":
                behaviors.append(plan)
            elif c.keyword == "sensor":
                sensors.append(plan)
            elif c.keyword == "stack":
                stack = plan
        triggers = []
        for tr in d.triggers:
            cond = ctx.lowering(signals=True).lower_formula(tr.condition, "a trigger condition")
            clause = _check_clause(ctx, tr.clause, d)
            if cond is not None and clause is not None:
                triggers.append(P.TriggerPlan(condition=cond, clause=clause))
        if d.is_ego:
            sensors = sensors or [DEFAULT_SENSOR]
            stack = stack or DEFAULT_STACK
        length, width = VEHICLE_KINDS[d.vehicle]
        if not all(k in vals for k in ("on", "lane", "at")):
            continue
        ctx.actors[d.name] = P.ActorPlan(
            name=d.name, vehicle=d.vehicle, road=vals["on"], lane=vals["lane"], s=vals["at"],
            speed=vals.get("speed", P.num(0.0)),
            length_m=_const_value(vals["length"]) if "length" in vals else length,
            width_m=_const_value(vals["width"]) if "width" in vals else width,
            mass_kg=_const_value(vals["mass"]) if "mass" in vals else 1500.0,
            wheelbase_m=_const_value(vals["wheelbase"]) if "wheelbase" in vals else 2.7,
            behaviors=behaviors, triggers=triggers, sensors=sensors, stack=stack,
            goal_s=vals.get("goal"))


_CLAUSE_TABLES = {"behavior": BEHAVIORS, "sensor": SENSORS, "stack": STACKS}


def _check_clause(ctx: Context, c: ast.Clause, actor: ast.ActorDecl) -> P.ClausePlan | None:
    table = _CLAUSE_TABLES.get(c.keyword)
    if table is None:
        ctx.sink.error("E0106", f"'{c.keyword}' is not supported in an actor block yet", c.span)
        return None
    if c.keyword in ("sensor", "stack") and not actor.is_ego:
        ctx.sink.error("E0204", f"only the ego has a {c.keyword}", c.span)
        return None
    cls = table.get(c.name)
    if cls is None:
        ctx.sink.error("E0106", f"unknown {c.keyword} '{c.name}'", c.name_span, *_suggest(c.name, table.names()),
                       f"{c.keyword}s: {', '.join(table.names())}")
        return None
    vals = check_settings(ctx, c.settings + c.block, cls.params, f"{c.keyword} '{c.name}'", c.span)
    return P.ClausePlan(keyword=c.keyword, name=c.name, settings=vals)


def _window_of(ctx: Context, timing: ast.Timing | None, span: Span):
    low = ctx.lowering(signals=False)
    if timing is None:
        return P.num(0.0), None
    start = low.lower_value(timing.start, units.TIME, "a fault time")
    if timing.kind == "at":
        return start, start
    if timing.kind == "from":
        return start, None
    end = low.lower_value(timing.end, units.TIME, "a fault time")
    return start, end


def rule_faults(ctx: Context) -> None:
    ego = ctx.actors.get("ego")
    # A sensor's name is its keyword (`sensor lidar`); each fault kind says which targets it takes.
    sensors = {s.name: s.name for s in ego.sensors} if ego else {}
    stack_cls = STACKS.get(ego.stack.name) if ego and ego.stack else None
    for block in ctx.blocks("faults"):
        for f in block.items:
            cls = FAULTS.get(f.kind)
            if cls is None:
                ctx.sink.error("E0106", f"unknown fault kind '{f.kind}'", f.kind_span,
                               *_suggest(f.kind, FAULTS.names()), f"fault kinds: {', '.join(FAULTS.names())}")
                continue
            target = ".".join(f.target)
            pool = cls.valid_targets(sensors, stack_cls)
            if target not in pool:
                ctx.sink.error("E0107", f"'{f.kind}' cannot target '{target}'", f.target_span,
                               *_suggest(target, pool),
                               f"valid targets: {', '.join(sorted(pool)) or '(none)'}")
                continue
            specs = (*cls.params, ParamSpec("seed", None, kind="int", low=0, high=2**31 - 1, doc="fault seed"))
            vals = check_settings(ctx, f.settings, specs, f"fault '{f.kind}'", f.span)
            seed = vals.pop("seed", None)
            start, end = _window_of(ctx, f.timing, f.span)
            if start is None or (f.timing is not None and f.timing.kind == "during" and end is None):
                continue
            _check_time_window(ctx, start, end, f.timing.span if f.timing else f.span)
            ctx.faults.append(P.FaultPlan(kind=f.kind, target=target, start_s=start, end_s=end, settings=vals,
                                          seed=int(_const_value(seed)) if seed is not None else None,
                                          source=f"{f.span.file}:{f.span.line}"))


def _check_time_window(ctx: Context, start, end, span: Span) -> None:
    dur = ctx.duration
    lo, hi = _const_value(start), _const_value(end) if end is not None else None
    if dur is None:
        return
    if lo is not None and not (0.0 <= lo <= dur):
        ctx.sink.error("E0302", f"time {_fmt(lo, units.TIME)} is outside the scenario (0 s to {_fmt(dur, units.TIME)})",
                       span)
    elif hi is not None and not (0.0 <= hi <= dur):
        ctx.sink.error("E0302", f"time {_fmt(hi, units.TIME)} is outside the scenario (0 s to {_fmt(dur, units.TIME)})",
                       span)
    elif lo is not None and hi is not None and hi < lo:
        ctx.sink.error("E0303", "the window ends before it starts", span)


NO_CLAUSES = {
    "collision": lambda actor, other: (
        E.Temporal(op="always", arg=E.Binary(op=">", left=E.Signal(name=f"clearance({actor})"), right=E.Num(value=0.0)))
        if other is None else
        E.Temporal(op="always", arg=E.Binary(op=">", left=E.Signal(name=f"distance({actor},{other})"),
                                             right=E.Num(value=0.0)))),
}


def rule_oracles(ctx: Context) -> None:
    seen: dict[str, Span] = {}
    for block in ctx.blocks("expect"):
        for i, o in enumerate(block.items):
            if o.no_what is not None:
                if o.no_what not in NO_CLAUSES:
                    ctx.sink.error("E0106", f"unknown built-in oracle 'no {o.no_what}'", o.span,
                                   f"built-ins: {', '.join('no ' + k for k in NO_CLAUSES)}")
                    continue
                if o.no_with is not None and o.no_with not in ctx.actors_ast:
                    ctx.sink.error("E0101", f"unknown actor '{o.no_with}'", o.span)
                    continue
                if o.no_with is not None:
                    formula = _collision_with(o.no_with)
                else:
                    formula = NO_CLAUSES[o.no_what]("ego", None)
                name = o.label or (f"no_{o.no_what}" + (f"_with_{o.no_with}" if o.no_with else ""))
            else:
                formula = ctx.lowering(signals=True).lower_formula(o.formula)
                if formula is None:
                    continue
                name = o.label or _auto_name(ctx, o)
            if name in seen:
                ctx.sink.error("E0102", f"oracle '{name}' is defined twice", o.span, f"first at {seen[name]}")
                continue
            seen[name] = o.span
            ctx.oracles.append(P.OraclePlan(name=name, severity=o.severity, formula=formula,
                                            text=_text_of(ctx, o.span)))


def _collision_with(other: str):
    # Box-to-box clearance between two actors is not a trace signal; use the ego's
    # clearance while the other actor is its nearest neighbour (distance as a guard).
    return E.Temporal(op="always", arg=E.Binary(op="or", left=E.Binary(
        op=">", left=E.Signal(name="clearance(ego)"), right=E.Num(value=0.0)), right=E.Binary(
        op=">", left=E.Signal(name=f"distance(ego,{other})"), right=E.Num(value=15.0))))


def _auto_name(ctx: Context, o: ast.OracleDecl) -> str:
    return f"oracle_{o.span.line}"


def _text_of(ctx: Context, span: Span) -> str:
    text = ctx.sources.get(span.file, "") if hasattr(ctx, "sources") else ""
    lines = text.splitlines()
    if span.line - 1 < len(lines):
        line = lines[span.line - 1]
        end = span.end_col - 1 if span.end_line == span.line else len(line)
        return line[span.col - 1:end].strip()
    return ""


def rule_goal_oracle(ctx: Context) -> None:
    """`goal 950 m` on the ego adds the oracle `eventually s(ego) >= goal`."""
    ego = ctx.actors.get("ego")
    if ego is None or ego.goal_s is None:
        return
    ctx.oracles.append(P.OraclePlan(
        name="reach_goal", severity="hard",
        formula=E.Temporal(op="eventually", arg=E.Binary(op=">=", left=E.Signal(name="s(ego)"), right=ego.goal_s)),
        text="ego reaches its goal"))


def rule_sweep(ctx: Context) -> None:
    grid, sampler, repeat, seed = [], None, 1, 0
    for block in ctx.blocks("sweep"):
        for item in block.items:
            if item.kind == "grid":
                if item.name not in ctx.param_dims:
                    ctx.sink.error("E0101", f"unknown parameter '{item.name}'", item.span,
                                   *_suggest(item.name, ctx.param_dims))
                    continue
                ctx.used_params.add(item.name)
                if not isinstance(item.value, ast.ListExpr):
                    ctx.sink.error("E0204", "a grid takes a list: `grid x in [1, 2, 3] m`", item.value.span)
                    continue
                vals = _lower_list(ctx, item.value, ctx.param_dims[item.name], f"the grid of '{item.name}'")
                if vals is not None:
                    grid.append(P.GridAxis(param=item.name, values=vals))
            elif item.kind in ("random", "halton", "lhs"):
                count = _int_of(ctx, item.value, "a sample count", 1, 1_000_000)
                s = dict((st.key, st) for st in item.settings)
                sseed = _int_of(ctx, s["seed"].value, "a seed", 0, 2**31 - 1) if "seed" in s else 0
                for st in item.settings:
                    if st.key != "seed":
                        ctx.sink.error("E0104", f"sampler has no setting '{st.key}'", st.key_span)
                if count is not None:
                    sampler = P.SamplerPlan(kind=item.kind, count=count, seed=sseed or 0)
            elif item.kind == "repeat":
                repeat = _int_of(ctx, item.value, "a repeat count", 1, 1_000_000) or 1
            elif item.kind == "seed":
                seed = _int_of(ctx, item.value, "a seed", 0, 2**31 - 1) or 0
    ctx.sweep = P.SweepPlan(grid=grid, sampler=sampler, repeat=repeat, seed=seed)


def _int_of(ctx: Context, node, what: str, lo: int, hi: int) -> int | None:
    e = ExprLowering(ctx.sink, Scope({}, set(), set(), False, set())).lower_value(node, units.DIMENSIONLESS, what)
    if e is None:
        return None
    v = _const_value(e)
    if v is None or v != int(v) or not (lo <= v <= hi):
        ctx.sink.error("E0301", f"{what} must be a whole number in [{lo}, {hi}]", node.span)
        return None
    return int(v)


def rule_unused(ctx: Context) -> None:
    for name, d in ctx.params_ast.items():
        if name not in ctx.used_params:
            ctx.sink.warning("W0001", f"parameter '{name}' is never used", d.span)


RULES = (
    rule_names,
    rule_header,
    rule_params,
    rule_roads,
    rule_assumptions,
    rule_actors,
    rule_faults,
    rule_oracles,
    rule_goal_oracle,
    rule_sweep,
    rule_unused,
)
