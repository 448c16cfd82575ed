"""Semantic checks: small rules, run in order, each adding diagnostics and checked pieces.

Like sqlglot's optimizer rules, each rule is a plain function of the `Context`; `RULES`
fixes their order (names before uses). Rules never stop at the first error: a broken
statement is reported and skipped, the rest is still checked.
"""

from __future__ import annotations

import difflib
import functools
import math
from dataclasses import dataclass, field

from addt_dsl import expr as E
from addt_dsl import plan as P
from addt_dsl import units
from addt_dsl.compiler import ast
from addt_dsl.compiler.exprs import ExprLowering, Scope, value_range
from addt_dsl.compiler.xodr_check import check_inline_road
from addt_dsl.diagnostics import DiagnosticSink, Span
from addt_dsl.registry import BEHAVIORS, FAULTS, GEOMETRIES, SENSORS, SIGNALS, STACKS, ParamSpec

HEADER = {
    "description": ParamSpec("description", None, kind="string", doc="free text"),
    "duration": ParamSpec("duration", units.TIME, required=True, low=0.1, high=3600.0, doc="simulated time"),
    "step": ParamSpec("step", units.TIME, default=0.01, low=0.001, high=0.1, doc="physics step"),
    "seed": ParamSpec("seed", None, kind="int", default=0, low=0, high=2**31 - 1, doc="base seed"),
    "run_seed": ParamSpec("run_seed", None, kind="int", low=0, high=2**32 - 1,
                          doc="pins every run's seed (replay files)"),
}

ACTOR_SETTINGS = (
    ParamSpec("on", None, kind="name", doc="road the actor starts on"),
    ParamSpec("lane", None, kind="int", low=-20, high=20, doc="lane id (OpenDRIVE: < 0 right of the reference line)"),
    ParamSpec("at", units.LENGTH, low=0.0, doc="station along the road"),
    ParamSpec("speed", units.SPEED, default=0.0, low=0.0, high=100.0, doc="initial speed"),
    ParamSpec("goal", units.LENGTH, low=0.0, doc="station the ego must reach (ego only)"),
    ParamSpec("length", units.LENGTH, low=0.1, high=30.0, doc="body length"),
    ParamSpec("width", units.LENGTH, low=0.1, high=5.0, doc="body width"),
    ParamSpec("mass", units.MASS, default=1500.0, low=50.0, high=60000.0, doc="mass"),
    ParamSpec("wheelbase", units.LENGTH, default=2.7, low=0.5, high=10.0, doc="wheelbase"),
    ParamSpec("mu", units.DIMENSIONLESS, default=0.8, low=0.05, high=1.5,
              doc="tyre-road friction coefficient (0.8 dry asphalt, 0.5 wet, 0.1 ice)"),
    ParamSpec("offset", units.LENGTH, default=0.0, low=-20.0, high=20.0,
              doc="start offset from the lane centre, left positive (e.g. a pedestrian on the kerb)"),
)

VEHICLE_KINDS = {"car": (4.6, 1.9), "truck": (12.0, 2.5), "pedestrian": (0.5, 0.5), "cyclist": (1.8, 0.6)}
DEFAULT_SENSOR = P.ClausePlan(keyword="sensor", name="lidar", settings={})
DEFAULT_STACK = P.ClausePlan(keyword="stack", name="bev", settings={})

INT_EPS = 1e-9


@dataclass
class RoadInfo:
    """What the compiler knows of a road's shape, for placement and lane checks."""

    length_m: float
    lane_ids: tuple[int, ...]  # lanes at s = 0 (inline roads: everywhere)
    lane_width_m: dict[int, float]  # narrowest width of each lane along the road


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
    road_info: dict[str, RoadInfo] = field(default_factory=dict)
    params: list[P.ParamPlan] = field(default_factory=list)
    param_dims: dict[str, units.Dim] = field(default_factory=dict)
    param_ranges: dict[str, tuple[float, float]] = field(default_factory=dict)
    assumptions: list[P.AssumptionPlan] = field(default_factory=list)
    actors: dict[str, P.ActorPlan] = field(default_factory=dict)
    faults: list[P.FaultPlan] = field(default_factory=list)
    oracles: list[P.OraclePlan] = field(default_factory=list)
    sweep: P.SweepPlan = field(default_factory=P.SweepPlan)
    used_params: set[str] = field(default_factory=set)
    read_file: object = None  # callable(path str, span) -> (display, text) | None
    sources: dict[str, str] = field(default_factory=dict)
    lines: dict[str, list[str]] = field(default_factory=dict)  # sources split, on demand
    current_road: str | None = None  # road of the actor being checked
    xodr_networks: dict = field(default_factory=dict)  # parsed imports by file
    _scopes: dict = field(default_factory=dict)

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
        scope = Scope(dict(self.param_dims), set(self.actors_ast), nodes | {"e2e"}, signals, self.used_params)
        self._scopes[key] = scope
        return scope

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
    except (E.UnboundParameter, TypeError, ValueError, OverflowError):
        return None


def _fmt(value, dim, unit: str | None = None) -> str:
    """An SI value for a message: in `unit` when the source used one (`20 %`, `72 km/h`),
    else in the dimension's canonical unit."""
    if value is None:
        return "…"
    if unit is not None and unit in units.UNITS:
        return f"{value / units.UNITS[unit].factor:.6g} {unit}"
    canonical = units.CANONICAL_UNIT.get(dim or units.DIMENSIONLESS)
    return f"{value:.6g} {canonical}" if canonical else f"{value:.6g}"


def _range_text(lo, hi, dim) -> str:
    return f"[{_fmt(lo, dim)}, {_fmt(hi, dim)}]"


def check_range(ctx: Context, expr, spec_low, spec_high, dim, what: str, span: Span,
                integer: bool = False, code: str = "E0301", unit: str | None = None) -> bool:
    """Check a value against [spec_low, spec_high]; a parameter-dependent value is checked
    over its parameters' ranges (interval arithmetic). False after reporting."""
    const = _const_value(expr)
    if const is not None:
        if not math.isfinite(const):
            ctx.sink.error("E0204", f"{what} is not a finite number", span)
            return False
        if integer and abs(const - round(const)) > INT_EPS:
            ctx.sink.error("E0204", f"{what} must be a whole number", span)
            return False
        if (spec_low is not None and const < spec_low) or (spec_high is not None and const > spec_high):
            shown = f"{_fmt(const, dim, unit)} = {_fmt(const, dim)}" if unit in ("%", "km/h", "mph", "ms") \
                else _fmt(const, dim)
            ctx.sink.error(code, f"{what} = {shown} is outside {_range_text(spec_low, spec_high, dim)}", span)
            return False
        return True
    got = value_range(expr, ctx.param_ranges)
    if got is None:
        return True
    lo, hi = got
    if (spec_low is not None and lo < spec_low - INT_EPS) or (spec_high is not None and hi > spec_high + INT_EPS):
        used = ", ".join(sorted(E.params_used(expr)))
        ctx.sink.error(code, f"{what} can be outside {_range_text(spec_low, spec_high, dim)}", span,
                       f"over the ranges of {used} it spans {_range_text(lo, hi, dim)}",
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
                           *_suggest(st.key, specs),
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
            ctx.sink.error("E0204", f"'{word}' is not a valid {st.key}", v.span, *_suggest(word, spec.choices),
                           f"one of: {', '.join(spec.choices)}")
            return None
        return word
    if isinstance(v, ast.ListExpr):
        ctx.sink.error("E0204", f"'{st.key}' takes one value, not a list", v.span)
        return None
    if isinstance(v, ast.Str):
        ctx.sink.error("E0204", f"'{st.key}' takes a number, not a string", v.span)
        return None
    want = spec.dim if spec.dim is not None else units.DIMENSIONLESS
    expr = low.lower_value(v, want, f"'{st.key}' of {what}")
    if expr is None:
        return None
    if not check_range(ctx, expr, spec.low, spec.high, spec.dim, f"'{st.key}'", v.span,
                       integer=spec.kind == "int", unit=_source_unit(v)):
        return None
    return expr


def _int_const(expr) -> int | None:
    v = _const_value(expr)
    return int(round(v)) if v is not None and math.isfinite(v) else None


# ---------------------------------------------------------------- rules

def rule_names(ctx: Context) -> None:
    """Collect declarations; duplicates are errors."""
    for kind, table in ((ast.RoadDecl, ctx.roads_ast), (ast.ParamDecl, ctx.params_ast),
                        (ast.ActorDecl, ctx.actors_ast)):
        for d in ctx.defs(kind):
            if d.name in table:
                ctx.sink.error("E0102", f"'{d.name}' is defined twice", d.span, f"first defined at {table[d.name].span}")
                continue
            if kind is ast.ActorDecl and d.name in ctx.params_ast:
                ctx.sink.error("E0102", f"'{d.name}' is already a parameter", d.span,
                               f"the parameter is defined at {ctx.params_ast[d.name].span}")
                continue
            table[d.name] = d
    egos = [a for a in ctx.defs(ast.ActorDecl) if a.is_ego]
    if not egos:
        ctx.sink.error("E0103", f"scenario '{ctx.scenario.name}' has no ego vehicle", ctx.scenario.span,
                       "add e.g. `ego car on road1 lane -1 at 10 m speed 20 m/s`")
    if not ctx.roads_ast:
        ctx.sink.error("E0103", f"scenario '{ctx.scenario.name}' has no road", ctx.scenario.span,
                       "add e.g. `road main { line length 500 m }`")


def rule_header(ctx: Context) -> None:
    values = check_settings(ctx, ctx.scenario.settings, HEADER.values(), "the scenario", ctx.scenario.span)
    for key, spec in HEADER.items():
        v = values.get(key, spec.default)
        if isinstance(v, (E.Num, E.Binary, E.Unary, E.Call, E.Param)):
            const = _const_value(v)
            if const is None:
                st = next(s for s in ctx.scenario.settings if s.key == key)
                ctx.sink.error("E0204", f"'{key}' must be a constant, not a parameter", st.value.span)
                continue
            v = const
        ctx.header[key] = v
    dur, step = ctx.header.get("duration"), ctx.header.get("step")
    if isinstance(dur, float) and isinstance(step, float) and step > dur:
        ctx.sink.error("E0301", "the physics step is longer than the scenario", ctx.scenario.span)


_PARAM_SETTINGS = ("dist", "mean", "sd", "integer")


def rule_params(ctx: Context) -> None:
    """Parameters: default, domain `in [lo, hi]` or choices, distribution."""
    for d in ctx.params_ast.values():
        plan = _check_param(ctx, d)
        if plan is not None:
            ctx.params.append(plan)
            ctx.param_ranges[d.name] = (plan.low, plan.high) if plan.low is not None else (plan.default,) * 2


def _check_param(ctx: Context, d: ast.ParamDecl) -> P.ParamPlan | None:
    """A parameter's plan, or None after a diagnostic. Its dimension is recorded as soon
    as the default is known, so uses elsewhere are still checked."""
    const_scope = Scope({}, set(), set(), False, set())
    low = ExprLowering(ctx.sink, const_scope)
    if isinstance(d.default, ast.Str):
        ctx.sink.error("E0204", f"the default of '{d.name}' must be a number, not a string", d.default.span)
        return None
    expr, ty = low.lower(d.default)
    if expr is None:
        return None
    if ty[0] != "num" or _const_value(expr) is None:
        ctx.sink.error("E0204", f"the default of '{d.name}' must be a constant number", d.default.span,
                       "parameters cannot depend on other parameters; relate them with `assume`")
        return None
    dim = ty[1]
    default = _const_value(expr)
    if not math.isfinite(default):
        ctx.sink.error("E0204", f"the default of '{d.name}' is not a finite number", d.default.span)
        return None
    ctx.param_dims[d.name] = dim
    opts: dict[str, ast.Setting] = {}
    for st in d.settings:
        if st.key not in _PARAM_SETTINGS:
            ctx.sink.error("E0104", f"parameter has no setting '{st.key}'", st.key_span,
                           *_suggest(st.key, _PARAM_SETTINGS), "settings of a parameter: dist, mean, sd, integer")
        elif st.key in opts:
            ctx.sink.error("E0102", f"setting '{st.key}' given twice", st.key_span)
        else:
            opts[st.key] = st
    dist = "uniform"
    if "dist" in opts:
        v = opts["dist"].value
        if isinstance(v, ast.Ref) and v.dotted in ("uniform", "normal", "choice"):
            dist = v.dotted
        else:
            ctx.sink.error("E0204", "`dist` is one of uniform, normal, choice", v.span)
            return None
    lo = hi = None
    choices: list[float] = []
    if d.domain is not None:
        if not isinstance(d.domain, ast.ListExpr):
            ctx.sink.error("E0204", f"the domain of '{d.name}' is a list: `in [low, high]` or `in [a, b, c]`",
                           d.domain.span)
            return None
        vals = _lower_list(ctx, d.domain, dim, f"the domain of '{d.name}'")
        if vals is None:
            return None
        # Two values are a range unless `dist choice`; three or more are choices.
        if len(vals) != 2 or dist == "choice":
            choices = vals
            lo, hi = min(vals), max(vals)
            if "dist" not in opts:
                dist = "choice"
            elif dist != "choice":
                ctx.sink.error("E0204", f"'{d.name}' lists {len(vals)} values, so it is a choice, "
                               f"not `dist {dist}`", d.domain.span, "a range is `in [low, high]`")
                return None
        else:
            lo, hi = vals
            if lo > hi:
                ctx.sink.error("E0303", f"the range of '{d.name}' is inverted: "
                               f"{_fmt(lo, dim)} > {_fmt(hi, dim)}", d.domain.span, "write `in [low, high]`")
                return None
        if choices and not any(abs(default - c) <= 1e-12 * max(1.0, abs(c)) for c in choices):
            ctx.sink.error("E0301", f"the default of '{d.name}' ({_fmt(default, dim)}) is not one of its choices",
                           d.default.span)
            return None
        if not choices and not (lo <= default <= hi):
            ctx.sink.error("E0301", f"the default of '{d.name}' ({_fmt(default, dim)}) is outside its range "
                           f"{_range_text(lo, hi, dim)}", d.default.span)
            return None
    elif dist == "choice":
        ctx.sink.error("E0105", f"choice parameter '{d.name}' needs its choices: `in [a, b, c]`", d.span)
        return None
    mean = sd = None
    if "mean" in opts:
        m_expr = low.lower_value(opts["mean"].value, dim, f"'mean' of '{d.name}'")
        mean = _const_value(m_expr) if m_expr is not None else None
        if mean is not None and not math.isfinite(mean):
            ctx.sink.error("E0204", f"'mean' of '{d.name}' is not a finite number", opts["mean"].value.span)
            return None
    if "sd" in opts:
        sd_expr = low.lower_value(opts["sd"].value, dim, f"'sd' of '{d.name}'")
        sd = _const_value(sd_expr) if sd_expr is not None else None
        if sd is not None and not (sd > 0 and math.isfinite(sd)):
            ctx.sink.error("E0301", f"'sd' of '{d.name}' must be positive", opts["sd"].value.span)
            return None
    if dist == "normal" and "sd" not in opts:
        ctx.sink.error("E0105", f"normal parameter '{d.name}' needs 'sd'", d.span,
                       f"e.g. `param {d.name} = ... dist normal sd ...`")
        return None
    if dist != "normal":
        for key in ("mean", "sd"):
            if key in opts:
                ctx.sink.warning("W0002", f"'{key}' has no effect on a {dist} parameter", opts[key].key_span,
                                 "add `dist normal`")
    integer = False
    if "integer" in opts:
        v = opts["integer"].value
        if isinstance(v, ast.Bool):
            integer = v.value
        else:
            ctx.sink.error("E0204", "`integer` is true or false", v.span)
            return None
    if integer:
        bad = [x for x in [default, *choices, *(b for b in (lo, hi) if b is not None)]
               if abs(x - round(x)) > INT_EPS]
        if bad:
            ctx.sink.error("E0204", f"integer parameter '{d.name}' has a fractional value {bad[0]!r}",
                           d.span)
            return None
    return P.ParamPlan(name=d.name, dimension=units.dim_name(dim), default=default,
                       low=lo, high=hi, distribution=dist, mean=mean, sd=sd,
                       choices=choices, integer=integer)


def _lower_list(ctx: Context, node: ast.ListExpr, dim, what: str) -> list[float] | None:
    vals = []
    low = ExprLowering(ctx.sink, Scope({}, set(), set(), False, set()))
    for item in node.items:
        if node.unit is not None and isinstance(item, ast.Number) and item.unit is None:
            item = ast.Number(item.span, item.value, node.unit)
        elif node.unit is not None and isinstance(item, ast.Number):
            ctx.sink.error("E0202", f"{what} has units on the list and on an item", item.span,
                           f"write `[1, 2, 3] {node.unit}` or give each item its unit")
            return None
        if isinstance(item, (ast.Str, ast.ListExpr)):
            ctx.sink.error("E0204", f"{what} must list numbers", item.span)
            return None
        e = low.lower_value(item, dim, what)
        if e is None:
            return None
        c = _const_value(e)
        if c is None or not math.isfinite(c):
            ctx.sink.error("E0204", f"{what} must list finite constants", item.span)
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
        segments, lanes, lanes_item, broken = [], None, None, False
        for item in d.items:
            cls = GEOMETRIES.get(item.kind)
            if cls is None:
                broken = True
                ctx.sink.error("E0106", f"unknown road element '{item.kind}'", item.span,
                               *_suggest(item.kind, GEOMETRIES.names()),
                               f"road elements: {', '.join(GEOMETRIES.names())}")
                continue
            vals = check_settings(ctx, item.settings, cls.params, f"'{item.kind}'", item.span)
            if any(p.required and p.name not in vals for p in cls.params):
                broken = True
                continue  # reported by check_settings
            consts = {k: _const_value(v) if not isinstance(v, str) else v for k, v in vals.items()}
            if any(v is None for v in consts.values()):
                broken = True
                ctx.sink.error("E0204", "road geometry must use constants, not parameters", item.span)
                continue
            spec = {p.name: p.default for p in cls.params}
            spec.update(consts)
            if item.kind == "lanes":
                if lanes is not None:
                    ctx.sink.error("E0102", "lanes given twice", item.span, f"first given at {lanes_item.span}")
                lanes, lanes_item = spec, item
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
        left, right = int(round(lanes["left"])), int(round(lanes["right"]))
        if left + right == 0:
            ctx.sink.error("E0204", f"road '{d.name}' has no lanes", lanes_item.span if lanes_item else d.span,
                           "e.g. `lanes right 2 width 3.5 m`")
            continue
        road_plan = P.RoadPlan(name=d.name, source="inline", segments=segments, left_lanes=left, right_lanes=right,
                               lane_width_m=lanes["width"], lane_offset_m=lanes["offset"])
        if not check_inline_road(ctx, road_plan, d.span):
            continue
        ctx.roads.append(road_plan)
        ids = tuple(range(left, 0, -1)) + tuple(range(-1, -right - 1, -1))
        ctx.road_info[d.name] = RoadInfo(sum(s.length_m for s in segments), ids,
                                         {i: lanes["width"] for i in ids})


def _import_road(ctx: Context, d: ast.RoadDecl) -> None:
    specs = (ParamSpec("road", None, kind="int", low=-(2**31), high=2**31 - 1,
                       doc="id of the road in the file to place actors on"),)
    vals = check_settings(ctx, d.import_settings, specs, "a road import", d.span)
    if not d.import_path.lower().endswith(".xodr"):
        ctx.sink.error("E0403", f"'{d.import_path}' is not an OpenDRIVE file", d.span,
                       "roads are imported from `.xodr` files")
        return
    got = ctx.read_file(d.import_path, d.span) if ctx.read_file else None
    if got is None:
        return
    display, text = got
    from addt_dsl.compiler.xodr_check import check_xodr

    checked = check_xodr(ctx, text, display, d.span, vals.get("road"))
    if checked is None:
        return
    road_id, info = checked
    ctx.roads.append(P.RoadPlan(name=d.name, source="xodr", xodr_file=display, xodr_text=text,
                                xodr_road_id=road_id))
    if info is not None:
        ctx.road_info[d.name] = info


def rule_assumptions(ctx: Context) -> None:
    names: dict[str, Span] = {}
    for d in ctx.defs(ast.AssumeDecl):
        if d.label is not None:
            if d.label in names:
                ctx.sink.error("E0102", f"constraint '{d.label}' is defined twice", d.span,
                               f"first defined at {names[d.label]}")
                continue
            names[d.label] = d.span
        low = ctx.lowering(signals=False)
        formula = low.lower_formula(d.expr, "a constraint")
        if formula is None:
            continue
        if not E.params_used(formula):
            holds = _const_value(formula)
            if holds is not None and not holds:
                ctx.sink.error("E0501", "this constraint never holds", d.expr.span,
                               "it uses no parameter, and it is false")
            else:
                ctx.sink.warning("W0002", "this constraint always holds: it uses no parameter", d.expr.span)
            continue
        ctx.assumptions.append(P.AssumptionPlan(name=d.label or "", text=_text_of(ctx, d.expr.span), expr=formula))


# ---------------------------------------------------------------- actors

def rule_actors(ctx: Context) -> None:
    order = _placement_order(ctx)
    for name in order:
        d = ctx.actors_ast[name]
        plan = _check_actor(ctx, d)
        if plan is not None:
            ctx.actors[d.name] = plan


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
                               *_suggest(p.actor, ctx.actors_ast),
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


def _check_actor(ctx: Context, d: ast.ActorDecl) -> P.ActorPlan | None:
    if d.vehicle not in VEHICLE_KINDS:
        ctx.sink.error("E0106", f"unknown vehicle kind '{d.vehicle}'", d.vehicle_span,
                       *_suggest(d.vehicle, VEHICLE_KINDS), f"kinds: {', '.join(VEHICLE_KINDS)}")
        return None
    what = "the ego" if d.is_ego else f"agent '{d.name}'"
    vals = check_settings(ctx, d.settings + d.block_settings, ACTOR_SETTINGS, what, d.span)
    length, width = VEHICLE_KINDS[d.vehicle]
    body = {"length": length, "width": width, "mass": 1500.0, "wheelbase": 2.7}
    for key in body:
        if key in vals:
            value = _const_value(vals[key])
            if value is None:
                span = next(st.value.span for st in d.settings + d.block_settings if st.key == key)
                ctx.sink.error("E0204", f"'{key}' must be a constant, not a parameter", span,
                               "the body and dynamics of an actor are fixed for a scenario")
                return None
            body[key] = value
    length, width = body["length"], body["width"]
    placement = _place(ctx, d, vals, length)
    ctx.current_road = placement[0] if placement is not None else None
    if placement is not None and "goal" in vals and d.is_ego:
        info = ctx.road_info.get(placement[0])
        span = next(st.value.span for st in d.settings + d.block_settings if st.key == "goal")
        if info is not None:
            check_range(ctx, vals["goal"], 0.0, info.length_m, units.LENGTH, "the goal", span)
    if "goal" in vals and not d.is_ego:
        span = next(s.key_span for s in d.settings + d.block_settings if s.key == "goal")
        ctx.sink.warning("W0002", "only the ego has a goal", span)
    behaviors, sensors, stack = [], [], None
    stack_span: Span | None = None
    sensor_spans: dict[str, Span] = {}
    for c in d.clauses:
        plan = _check_clause(ctx, c, d)
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
    triggers = [t for t in (_lower_step(ctx, s, d) for s in d.steps) if t is not None]
    if d.is_ego:
        sensors = sensors or [DEFAULT_SENSOR]
        stack = stack or DEFAULT_STACK
        _check_stack_sensors(ctx, stack, sensors, stack_span or d.span)
        _check_sensor_expectations(ctx, stack, sensors, sensor_spans, stack_span or d.span)
    if placement is None:
        return None
    road, lane, s = placement
    return P.ActorPlan(
        name=d.name, vehicle=d.vehicle, road=road, lane=lane, s=s,
        speed=vals.get("speed", P.num(0.0)),
        length_m=length, width_m=width, mass_kg=body["mass"], wheelbase_m=body["wheelbase"],
        behaviors=behaviors, triggers=triggers, sensors=sensors, stack=stack,
        goal_s=vals.get("goal"), mu=vals.get("mu"), offset=vals.get("offset"))


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
        wanted = [f"{key} {_fmt(want, dims[key], 'deg' if dims[key] == units.ANGLE else None)}"
                  for key, want in mismatches(words, sensor.name, values)]
        if wanted:
            ctx.sink.warning("W0003", f"{words.get('perception', 'this')} perception is made for a "
                                      f"{sensor.name} with {', '.join(wanted)}", spans.get(sensor.name, span),
                             "it runs, but expect worse detection")


def _place(ctx: Context, d: ast.ActorDecl, vals: dict, length: float):
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
        if p.actor not in ctx.actors:
            return None  # the reference failed to check (or a cycle): reported there
    road = vals.get("on")
    road_span = next((s.value.span for s in d.settings + d.block_settings if s.key == "on"), d.span)
    if road is not None and road not in ctx.roads_ast:
        ctx.sink.error("E0101", f"unknown road '{road}'", road_span, *_suggest(road, ctx.roads_ast),
                       f"roads: {', '.join(sorted(ctx.roads_ast))}")
        return None
    for p in refs:
        other_road = ctx.actors[p.actor].road
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
        lane = _lane_relative(p.kind, ctx.actors[p.actor].lane)
        lane_span = p.span
    if along:
        p = along[0]
        other = ctx.actors[p.actor]
        dist = ctx.lowering().lower_value(p.distance, units.LENGTH, f"the distance {p.kind} '{p.actor}'")
        if dist is None:
            return None
        check_range(ctx, dist, 0.0, None, units.LENGTH, "the gap", p.distance.span)
        # The distance is a bumper-to-bumper gap, so half of both lengths is added.
        half = E.Num(value=0.5 * (other.length_m + length))
        offset = E.Binary(op="+", left=dist, right=half)
        s = E.Binary(op="+" if p.kind == "ahead" else "-", left=other.s, right=offset)
        s_span = p.span
    else:
        s = vals["at"]
        s_span = next(st.value.span for st in d.settings + d.block_settings if st.key == "at")
    _check_on_road(ctx, d, road, lane, lane_span, s, s_span)
    return road, lane, s


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
    const = _const_value(result)
    return E.Num(value=float(round(const))) if const is not None else result


def _check_on_road(ctx: Context, d: ast.ActorDecl, road: str, lane, lane_span: Span, s, s_span: Span) -> None:
    info = ctx.road_info.get(road)
    if info is None:
        return
    check_range(ctx, s, 0.0, info.length_m, units.LENGTH, f"the position of '{d.name}' along '{road}'", s_span)
    lane_c = _int_const(lane)
    if lane_c is not None:
        if lane_c not in info.lane_ids:
            ctx.sink.error("E0301", f"road '{road}' has no lane {lane_c}", lane_span,
                           f"lanes of '{road}': {', '.join(str(i) for i in info.lane_ids)}",
                           "lane ids are negative right of the reference line (-1, -2, ...), positive left")
    else:
        got = value_range(lane, ctx.param_ranges)
        if got is not None and info.lane_ids:
            lo, hi = min(info.lane_ids), max(info.lane_ids)
            if got[0] < lo or got[1] > hi:
                ctx.sink.error("E0301", f"the lane of '{d.name}' can be outside the lanes of '{road}'", lane_span,
                               f"it spans [{got[0]:g}, {got[1]:g}]; lanes: {', '.join(str(i) for i in info.lane_ids)}")


def _check_lateral_conflicts(ctx: Context, d: ast.ActorDecl) -> None:
    lateral = [c for c in d.clauses if c.keyword == "behavior" and c.name in ("lane_change", "cut_in")]
    if len(lateral) > 1:
        ctx.sink.warning("W0002", "two lane changes start at once; only the last one has an effect",
                         lateral[1].span, "order them with `sequence { ... }` or `at`/`after`")


_CLAUSE_TABLES = {"behavior": BEHAVIORS, "sensor": SENSORS, "stack": STACKS}


def _check_clause(ctx: Context, c: ast.Clause, actor: ast.ActorDecl) -> P.ClausePlan | None:
    table = _CLAUSE_TABLES[c.keyword]
    if c.keyword in ("sensor", "stack") and not actor.is_ego:
        ctx.sink.error("E0204", f"only the ego has a {c.keyword}", c.span,
                       "traffic agents follow behaviours")
        return None
    if c.keyword == "behavior" and actor.is_ego:
        ctx.sink.error("E0204", "the ego is driven by its stack, not by behaviours", c.span,
                       "configure the stack instead, e.g. `stack bev cruise_speed 20 m/s`")
        return None
    cls = table.get(c.name)
    if cls is None:
        ctx.sink.error("E0106", f"unknown {c.keyword} '{c.name}'", c.name_span, *_suggest(c.name, table.names()),
                       f"{c.keyword}s: {', '.join(table.names())}")
        return None
    vals = check_settings(ctx, c.settings + c.block, cls.params, f"{c.keyword} '{c.name}'", c.span)
    if c.keyword == "behavior" and getattr(cls, "channel", "") == "lateral" and "to" in vals:
        _check_target_lane(ctx, c, vals["to"])
    for spec in cls.params:  # a `name` setting of a behaviour names another actor
        if c.keyword == "behavior" and spec.kind == "name" and isinstance(vals.get(spec.name), str):
            other = vals[spec.name]
            if other not in ctx.actors_ast or other == actor.name:
                span = next(st.value.span for st in c.settings + c.block if st.key == spec.name)
                pool = [a for a in ctx.actors_ast if a != actor.name]
                ctx.sink.error("E0101", f"unknown actor '{other}'" if other != actor.name
                               else f"'{other}' cannot {c.name} itself", span, *_suggest(other, pool),
                               f"actors: {', '.join(sorted(pool))}")
                return None
    return P.ClausePlan(keyword=c.keyword, name=c.name, settings=vals)


def _check_target_lane(ctx: Context, c: ast.Clause, lane) -> None:
    """A lane change must aim at a lane of the actor's road."""
    info = ctx.road_info.get(ctx.current_road or "")
    if info is None or not info.lane_ids:
        return
    span = next((st.value.span for st in c.settings + c.block if st.key == "to"), c.span)
    lane_c = _int_const(lane)
    if lane_c is not None:
        if lane_c not in info.lane_ids:
            ctx.sink.error("E0301", f"road '{ctx.current_road}' has no lane {lane_c}", span,
                           f"lanes of '{ctx.current_road}': {', '.join(str(i) for i in info.lane_ids)}")
        return
    got = value_range(lane, ctx.param_ranges)
    if got is not None and (got[0] < min(info.lane_ids) or got[1] > max(info.lane_ids)):
        ctx.sink.error("E0301", f"the target lane can be outside the lanes of '{ctx.current_road}'", span,
                       f"it spans [{got[0]:g}, {got[1]:g}]; lanes: {', '.join(str(i) for i in info.lane_ids)}")


def _lower_step(ctx: Context, node, actor: ast.ActorDecl) -> P.TriggerPlan | None:
    """A step or group of an actor's block → TriggerPlan (groups become a step without
    a start condition that arms the group)."""
    if actor.is_ego:
        ctx.sink.error("E0204", "the ego is driven by its stack; steps and triggers are for agents", node.span)
        return None
    if isinstance(node, ast.Clause):
        clause = _check_clause(ctx, node, actor)
        return P.TriggerPlan(clause=clause) if clause is not None else None
    if isinstance(node, ast.Group):
        group = _lower_group(ctx, node, actor)
        return P.TriggerPlan(group=group) if group is not None else None
    starts: dict[str, ast.StepStart] = {}
    ok = True
    for st in node.starts:
        if st.kind in starts:
            ctx.sink.error("E0102", f"`{st.kind}` given twice in one step", st.span)
            ok = False
        starts[st.kind] = st
    at = after = condition = None
    low = ctx.lowering()
    for kind in ("at", "after"):
        if kind in starts:
            value = low.lower_value(starts[kind].value, units.TIME, f"the time of `{kind}`")
            if value is None:
                ok = False
                continue
            if not _check_time(ctx, value, starts[kind].value.span, f"`{kind}`"):
                ok = False
            if kind == "at":
                at = value
            else:
                after = value
    if "when" in starts:
        cond_node = starts["when"].value
        condition = ctx.lowering(signals=True).lower_formula(cond_node, "a trigger condition")
        if condition is None:
            ok = False
        elif any(isinstance(n, (E.Temporal, E.Until)) for n in E.walk(condition)):
            ctx.sink.error("E0204", "a trigger condition is checked at each instant; it cannot use "
                           "always/eventually/until", cond_node.span,
                           "write the condition on the current state, e.g. `when gap(ego, lead) < 20 m`")
            ok = False
    if isinstance(node.action, ast.Group):
        group = _lower_group(ctx, node.action, actor)
        clause = None
        ok = ok and group is not None
    else:
        clause = _check_clause(ctx, node.action, actor)
        group = None
        ok = ok and clause is not None
    if not ok:
        return None
    return P.TriggerPlan(condition=condition, clause=clause, at_s=at, after_s=after, group=group)


def _lower_group(ctx: Context, node: ast.Group, actor: ast.ActorDecl) -> P.GroupPlan | None:
    if not node.items:
        ctx.sink.error("E0103", f"empty `{node.mode}` block", node.span)
        return None
    steps = [_lower_step(ctx, item, actor) for item in node.items]
    if any(s is None for s in steps):
        return None
    return P.GroupPlan(mode=node.mode, steps=steps)


def _check_time(ctx: Context, value, span: Span, what: str) -> bool:
    """A time must lie in [0, duration] (E0302 otherwise)."""
    dur = ctx.duration
    what = what if what.startswith("the") else f"the time of {what}"
    return check_range(ctx, value, 0.0, dur if isinstance(dur, float) else None, units.TIME, what, span,
                       code="E0302")


# ---------------------------------------------------------------- faults

def _window_of(ctx: Context, timing: ast.Timing | None):
    low = ctx.lowering(signals=False)
    if timing is None:
        return P.num(0.0), None
    start = low.lower_value(timing.start, units.TIME, "a fault time")
    if start is None:
        return None, None
    if timing.kind == "at":
        if timing.length is not None:
            length = low.lower_value(timing.length, units.TIME, "a fault duration")
            if length is None:
                return None, None
            if not check_range(ctx, length, 0.0, None, units.TIME, "the fault's duration", timing.length.span):
                return None, None
            return start, _simplify(E.Binary(op="+", left=start, right=length))
        return start, start
    if timing.kind == "from":
        return start, None
    end = low.lower_value(timing.end, units.TIME, "a fault time")
    return start, end


def _simplify(expr):
    const = _const_value(expr)
    return E.Num(value=const) if const is not None else expr


def rule_faults(ctx: Context) -> None:
    # Targets come from the ego's declaration, so a fault is checked even when the ego
    # itself had an error elsewhere.
    ego = ctx.actors_ast.get("ego")
    clauses = ego.clauses if ego else ()
    sensors = {c.name for c in clauses if c.keyword == "sensor"} or {DEFAULT_SENSOR.name}
    stack_name = next((c.name for c in clauses if c.keyword == "stack"), DEFAULT_STACK.name)
    stack_cls = STACKS.get(stack_name)
    sites = _fault_sites(ctx, stack_cls) if stack_cls else set()
    for block in ctx.blocks("faults"):
        for f in block.items:
            cls = FAULTS.get(f.kind)
            if cls is None:
                ctx.sink.error("E0106", f"unknown fault kind '{f.kind}'", f.kind_span,
                               *_suggest(f.kind, FAULTS.names()), f"fault kinds: {', '.join(FAULTS.names())}")
                continue
            target = ".".join(f.target)
            # Each kind says which targets it takes (an image fault only a camera, a bit flip
            # a site or a whole node); sites come with the ego's stack settings (tensors).
            pool = cls.valid_targets({name: name for name in sensors}, stack_cls)
            if cls.target_kind == "site" and stack_cls is not None:
                pool = (pool - set(stack_cls.fault_sites())) | sites
            if target not in pool:
                what = {"sensor": "sensors of the ego", "site": "fault sites of the stack",
                        "node": "nodes of the stack"}[cls.target_kind]
                ctx.sink.error("E0107", f"'{f.kind}' cannot target '{target}'", f.target_span,
                               *_suggest(target, pool),
                               f"{what}: {', '.join(sorted(pool)) or '(none)'}")
                continue
            specs = (*cls.params, ParamSpec("seed", None, kind="int", low=0, high=2**32 - 1, doc="fault seed"))
            vals = check_settings(ctx, f.settings, specs, f"fault '{f.kind}'", f.span)
            seed = vals.pop("seed", None)
            start, end = _window_of(ctx, f.timing)
            if start is None or (f.timing is not None and f.timing.kind == "during" and end is None):
                continue
            if not _check_window(ctx, start, end, f.timing.span if f.timing else f.span):
                continue
            ctx.faults.append(P.FaultPlan(kind=f.kind, target=target, start_s=start, end_s=end, settings=vals,
                                          seed=_int_const(seed) if seed is not None else None,
                                          source=f"{f.span.file}:{f.span.line}"))


def _fault_sites(ctx: Context, stack_cls) -> set[str]:
    """The stack's fault sites for the ego's stack settings (a stack whose sites depend on
    its settings, e.g. tensor sites with `perception learned`, takes them as an argument)."""
    if not _takes_settings(stack_cls):
        return set(stack_cls.fault_sites())
    ego = ctx.actors.get("ego")
    lowered = ego.stack.settings if ego is not None and ego.stack is not None else {}
    settings = {k: v if isinstance(v, str) else _const_value(v) for k, v in lowered.items()}
    return set(stack_cls.fault_sites({k: v for k, v in settings.items() if v is not None}))


@functools.lru_cache(maxsize=None)
def _takes_settings(stack_cls) -> bool:
    import inspect

    try:
        return len(inspect.signature(stack_cls.fault_sites).parameters) >= 1
    except (TypeError, ValueError):
        return False


def _check_window(ctx: Context, start, end, span: Span) -> bool:
    if not _check_time(ctx, start, span, "the fault's start"):
        return False
    if end is not None and end is not start and not _check_time(ctx, end, span, "the fault's end"):
        return False
    lo, hi = _const_value(start), _const_value(end) if end is not None else None
    if lo is not None and hi is not None and hi < lo:
        ctx.sink.error("E0303", "the window ends before it starts", span,
                       f"[{_fmt(lo, units.TIME)}, {_fmt(hi, units.TIME)}]")
        return False
    return True


# ---------------------------------------------------------------- oracles

def _always(formula):
    return E.Temporal(op="always", arg=formula)


def _collision_with(other: str):
    # Box-to-box clearance between two actors is not a trace signal; use the ego's
    # clearance while the other actor is its nearest neighbour (distance as a guard).
    return _always(E.Binary(op="or", left=E.Binary(
        op=">", left=E.Signal(name="clearance(ego)"), right=E.Num(value=0.0)), right=E.Binary(
        op=">", left=E.Signal(name=f"distance(ego,{other})"), right=E.Num(value=15.0))))


BUILTIN_NAMES = ("no collision", "stay in lane", "reach goal", "min SIGNAL", "max SIGNAL")

# `no collision [with X]` → formula; the printer recognises built-ins through this table.
NO_CLAUSES = {
    "collision": lambda actor, other: (
        _always(E.Binary(op=">", left=E.Signal(name=f"clearance({actor})"), right=E.Num(value=0.0)))
        if other is None else _collision_with(other)),
}


def _builtin(ctx: Context, b: ast.Builtin) -> tuple[E.Expr, str] | None:
    """Lower a built-in oracle to (STL formula, default name)."""
    if b.kind == "no":
        if b.word != "collision":
            ctx.sink.error("E0106", f"unknown built-in oracle 'no {b.word}'", b.word_span,
                           "built-ins: " + ", ".join(BUILTIN_NAMES))
            return None
        if b.actor is None:
            return NO_CLAUSES["collision"]("ego", None), "no_collision"
        if b.actor not in ctx.actors_ast or b.actor == "ego":
            ctx.sink.error("E0101", f"unknown agent '{b.actor}'", b.actor_span,
                           *_suggest(b.actor, [a for a in ctx.actors_ast if a != "ego"]))
            return None
        return _collision_with(b.actor), f"no_collision_with_{b.actor}"
    if b.kind == "stay_in_lane":
        return _stay_in_lane(ctx, b)
    if b.kind == "reach_goal":
        ego = ctx.actors.get("ego")
        if ego is None:
            return None
        if ego.goal_s is None:
            ctx.sink.error("E0105", "`reach goal` needs a goal on the ego", b.span,
                           "add e.g. `goal 600 m` to the ego")
            return None
        hi = None
        if b.value is not None:
            hi_e = ctx.lowering().lower_value(b.value, units.TIME, "the time limit")
            if hi_e is None:
                return None
            hi = _const_value(hi_e)
            if hi is None:
                ctx.sink.error("E0204", "the time limit must be a constant", b.value.span)
                return None
            if not _check_time(ctx, hi_e, b.value.span, "the time limit"):
                return None
        return E.Temporal(op="eventually", lo_s=0.0, hi_s=hi, arg=E.Binary(
            op=">=", left=E.Signal(name="s(ego)"), right=ego.goal_s)), "reach_goal"
    return _bound(ctx, b)


def _stay_in_lane(ctx: Context, b: ast.Builtin):
    vals = check_settings(ctx, b.settings, (ParamSpec("tolerance", units.LENGTH, default=0.0, low=0.0, high=10.0,
                                                      doc="how far the body may cross the lane border"),),
                          "`stay in lane`", b.span)
    ego = ctx.actors.get("ego")
    if ego is None:
        return None
    tol = _const_value(vals["tolerance"]) if "tolerance" in vals else 0.0
    if tol is None:
        ctx.sink.error("E0204", "the tolerance must be a constant", b.span)
        return None
    info = ctx.road_info.get(ego.road)
    lane = _int_const(ego.lane)
    if info is not None and lane is not None and lane in info.lane_width_m:
        lane_width = info.lane_width_m[lane]
    elif info is not None and info.lane_width_m:
        lane_width = min(info.lane_width_m.values())
    else:
        lane_width = 3.5
    margin = 0.5 * (lane_width - ego.width_m) + tol
    if margin <= 0:
        ctx.sink.error("E0301", f"the ego ({_fmt(ego.width_m, units.LENGTH)} wide) does not fit in its lane "
                       f"({_fmt(lane_width, units.LENGTH)})", b.span, "add a `tolerance`")
        return None
    # Body inside the lane: |offset of the centre| + half the width <= half the lane.
    return _always(E.Binary(op="<=", left=E.Call(fn="abs", args=(E.Signal(name="lane_offset(ego)"),)),
                            right=E.Num(value=margin))), "stay_in_lane"


def _bound(ctx: Context, b: ast.Builtin):
    """`min SIGNAL [to|of X] V` → always SIGNAL >= V; `max ...` → always |SIGNAL| <= V."""
    cls = SIGNALS.get(b.word)
    if cls is None:
        ctx.sink.error("E0101", f"unknown signal '{b.word}'", b.word_span, *_suggest(b.word, SIGNALS.names()),
                       f"signals: {', '.join(SIGNALS.names())}")
        return None
    scope = ctx.scope(True)
    agents = [a for a in ctx.actors_ast if a != "ego"]
    if cls.args == ("actor",):
        arg_sets = [(b.actor or "ego",)]
        pool = scope.actors
    elif cls.args == ("actor", "actor"):
        if b.actor is not None:
            arg_sets = [("ego", b.actor)]
        elif agents:
            arg_sets = [("ego", a) for a in agents]
        else:
            ctx.sink.error("E0103", f"`{b.kind} {b.word}` compares the ego with other actors, and there are none",
                           b.span)
            return None
        pool = scope.actors
    elif cls.args == ("node",):
        arg_sets = [(b.actor or "e2e",)]
        pool = scope.nodes
    else:
        if b.actor is not None:
            ctx.sink.error("E0204", f"signal '{b.word}' takes no actor", b.actor_span)
            return None
        arg_sets = [()]
        pool = set()
    if b.actor is not None and b.actor not in pool:
        kind = "node" if cls.args == ("node",) else "actor"
        ctx.sink.error("E0101", f"unknown {kind} '{b.actor}'", b.actor_span, *_suggest(b.actor, pool),
                       f"{kind}s: {', '.join(sorted(pool))}")
        return None
    if cls.args == ("actor", "actor") and b.actor == "ego":
        ctx.sink.error("E0204", f"`{b.kind} {b.word}` compares the ego with another actor", b.actor_span)
        return None
    limit = ctx.lowering().lower_value(b.value, cls.dim, f"the limit of `{b.kind} {b.word}`")
    if limit is None:
        return None
    parts = []
    for args in arg_sets:
        sig = E.Signal(name=f"{b.word}({','.join(args)})")
        if b.kind == "min":
            parts.append(E.Binary(op=">=", left=sig, right=limit))
        else:
            parts.append(E.Binary(op="<=", left=E.Call(fn="abs", args=(sig,)), right=limit))
    formula = parts[0]
    for p in parts[1:]:
        formula = E.Binary(op="and", left=formula, right=p)
    name = f"{b.kind}_{b.word}" + (f"_{'to' if len(cls.args) == 2 else 'of'}_{b.actor}" if b.actor else "")
    return _always(formula), name


def rule_oracles(ctx: Context) -> None:
    seen: dict[str, Span] = {}
    for block in ctx.blocks("expect"):
        for o in block.items:
            if o.builtin is not None:
                got = _builtin(ctx, o.builtin)
                if got is None:
                    continue
                formula, default_name = got
                name = o.label or default_name
            else:
                formula = ctx.lowering(signals=True).lower_formula(o.formula)
                if formula is None:
                    continue
                if not _check_formula_windows(ctx, formula, o.formula.span):
                    continue
                name = o.label or _auto_name(ctx, o)
            if name in seen:
                ctx.sink.error("E0102", f"oracle '{name}' is defined twice", o.span, f"first at {seen[name]}",
                               "give one of them a name: `my_name: ...`")
                continue
            seen[name] = o.span
            ctx.oracles.append(P.OraclePlan(name=name, severity=o.severity, formula=formula,
                                            text=_text_of(ctx, o.span)))


def _check_formula_windows(ctx: Context, formula, span: Span) -> bool:
    """Time windows of temporal operators must end within the scenario."""
    dur = ctx.duration
    if not isinstance(dur, float):
        return True
    for node in E.walk(formula):
        if isinstance(node, (E.Temporal, E.Until)):
            for bound in (node.lo_s, node.hi_s):
                if bound is not None and bound > dur + 1e-9:
                    ctx.sink.error("E0302", f"the time window reaches {_fmt(bound, units.TIME)}, beyond the "
                                   f"scenario's duration ({_fmt(dur, units.TIME)})", span,
                                   "shorten the window or lengthen `duration`")
                    return False
    return True


def _auto_name(ctx: Context, o: ast.OracleDecl) -> str:
    return f"oracle_{o.span.line}"


def _text_of(ctx: Context, span: Span) -> str:
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


def rule_goal_oracle(ctx: Context) -> None:
    """`goal 950 m` on the ego adds the oracle `eventually s(ego) >= goal`, unless the
    expect block states `reach goal` itself."""
    ego = ctx.actors.get("ego")
    if ego is None or ego.goal_s is None:
        return
    if any(o.name == "reach_goal" for o in ctx.oracles):
        return
    explicit = any(o.builtin is not None and o.builtin.kind == "reach_goal"
                   for b in ctx.blocks("expect") for o in b.items)
    if explicit:
        return
    ctx.oracles.append(P.OraclePlan(
        name="reach_goal", severity="hard",
        formula=E.Temporal(op="eventually", arg=E.Binary(op=">=", left=E.Signal(name="s(ego)"), right=ego.goal_s)),
        text="ego reaches its goal"))


# ---------------------------------------------------------------- sweeps

def rule_sweep(ctx: Context) -> None:
    grid, sampler, repeat, seed, max_rej = [], None, 1, 0, P.SweepPlan().max_rejections
    seen: dict[str, Span] = {}
    sampler_span: Span | None = None
    for block in ctx.blocks("sweep"):
        for item in block.items:
            key = item.name if item.kind == "grid" else ("sampler" if item.kind in ("random", "halton", "lhs")
                                                          else item.kind)
            if key in seen:
                ctx.sink.error("E0102", f"{'grid of ' + key if item.kind == 'grid' else key} given twice",
                               item.span, f"first given at {seen[key]}")
                continue
            seen[key] = item.span
            if item.kind == "grid":
                if item.name not in ctx.param_dims:
                    ctx.sink.error("E0101", f"unknown parameter '{item.name}'", item.span,
                                   *_suggest(item.name, ctx.param_dims))
                    continue
                if not isinstance(item.value, ast.ListExpr):
                    ctx.sink.error("E0204", "a grid takes a list: `grid x in [1, 2, 3] m`", item.value.span)
                    continue
                vals = _lower_list(ctx, item.value, ctx.param_dims[item.name], f"the grid of '{item.name}'")
                if vals is None:
                    continue
                p = next((p for p in ctx.params if p.name == item.name), None)
                if p is not None and p.low is not None:
                    outside = [v for v in vals if v < p.low - 1e-12 or v > p.high + 1e-12]
                    if outside:
                        dim = ctx.param_dims[item.name]
                        unit = item.value.unit or _source_unit(ctx.params_ast[item.name].default)
                        ctx.sink.error("E0301", f"grid value {_fmt(outside[0], dim, unit)} is outside the range of "
                                       f"'{item.name}' [{_fmt(p.low, dim, unit)}, {_fmt(p.high, dim, unit)}]",
                                       item.value.span, "a parameter's range is its domain: widen it to "
                                       "include the grid")
                        continue
                if p is not None and p.integer and any(abs(v - round(v)) > INT_EPS for v in vals):
                    ctx.sink.error("E0204", f"'{item.name}' is an integer parameter; the grid has fractions",
                                   item.value.span)
                    continue
                grid.append(P.GridAxis(param=item.name, values=vals))
            elif item.kind in ("random", "halton", "lhs"):
                count = _int_of(ctx, item.value, "a sample count", 1, 1_000_000)
                sseed = 0
                for st in item.settings:
                    if st.key == "seed":
                        sseed = _int_of(ctx, st.value, "a seed", 0, 2**31 - 1) or 0
                    else:
                        ctx.sink.error("E0104", f"sampler has no setting '{st.key}'", st.key_span,
                                       "settings of a sampler: seed")
                if count is not None:
                    sampler = P.SamplerPlan(kind=item.kind, count=count, seed=sseed)
                    sampler_span = item.span
            elif item.kind == "repeat":
                repeat = _int_of(ctx, item.value, "a repeat count", 1, 1_000_000) or 1
            elif item.kind == "seed":
                seed = _int_of(ctx, item.value, "a seed", 0, 2**31 - 1) or 0
            elif item.kind == "max_rejections":
                got = _int_of(ctx, item.value, "a rejection cap", 0, 10_000_000)
                max_rej = got if got is not None else max_rej
    if sampler is not None:
        gridded = {g.param for g in grid}
        sampled = [p for p in ctx.params if p.name not in gridded and
                   (p.choices or (p.low is not None and p.low < p.high))]
        if not sampled:
            ctx.sink.warning("W0002", f"`{sampler.kind}` has nothing to sample", sampler_span,
                             "give a parameter a range (`in [low, high]`) that no grid fixes")
    ctx.sweep = P.SweepPlan(grid=grid, sampler=sampler, repeat=repeat, seed=seed, max_rejections=max_rej)


def _source_unit(node) -> str | None:
    return node.unit if isinstance(node, ast.Number) else None


def _int_of(ctx: Context, node, what: str, lo: int, hi: int) -> int | None:
    e = ExprLowering(ctx.sink, Scope({}, set(), set(), False, set())).lower_value(node, units.DIMENSIONLESS, what)
    if e is None:
        return None
    v = _const_value(e)
    if v is None or not math.isfinite(v) or v != int(v) or not (lo <= v <= hi):
        ctx.sink.error("E0301", f"{what} must be a whole number in [{lo}, {hi}]", node.span)
        return None
    return int(v)


def rule_unused(ctx: Context) -> None:
    for name, d in ctx.params_ast.items():
        checked = any(p.name == name for p in ctx.params)  # a broken one is reported already
        if checked and name not in ctx.used_params:
            ctx.sink.warning("W0001", f"parameter '{name}' is never used", d.span,
                             "use it in a setting, a constraint or an oracle, or remove it")


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
