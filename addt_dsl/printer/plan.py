"""`ScenarioPlan` / `RunSpec` → `.addt` source: every failure becomes a replayable file.

Two entry points:

- `print_plan(plan)` prints a plan as it is (parameter ranges, distributions, sweep);
  compiling the text gives the same plan again, up to provenance (file names, source
  lines, the oracles' source text).
- `print_spec(spec)` prints one run: `pin_spec` first turns the RunSpec into the plan
  of exactly that run (parameters fixed at their values, no sweep, the concrete faults
  with their seeds, `run_seed` pinned), then `print_plan` prints it. Compiling and
  expanding the text gives back `pin_spec(spec)` (see `semantic_key`), and running it
  gives the same trace, bit for bit.

Table-driven: `SECTIONS` lists the parts of a scenario in print order and `HEADER` the
header settings; road geometry elements, behaviours, sensors and faults print from their
registered class. A new construct is a row (and a function) in one of them. Values and
formulas are printed by `printer.expr`.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
import tempfile
from collections.abc import Callable
from pathlib import Path

from addt_dsl import expr as E
from addt_dsl import units
from addt_dsl.compiler import compile_source
from addt_dsl.compiler.rules.actors import CLAUSE_TABLES
from addt_dsl.compiler.rules.lights import CONTROLLER_SPECS, LIGHT_CLAUSE_SPECS
from addt_dsl.compiler.rules.oracles import EGO_ONLY, NO_CLAUSES, reach_goal_formula
from addt_dsl.diagnostics import render_text
from addt_dsl.limits import DEFAULT as DEFAULT_LIMITS
from addt_dsl.limits import Limits
from addt_dsl.plan import (ActorPlan, ClausePlan, ConcreteFault, FaultPlan, OraclePlan, ParamPlan, RoadPlan,
                           RunSpec, ScenarioPlan, SweepPlan, TriggerPlan)
from addt_dsl.printer.expr import (ExprPrinter, PrinterError, dim_of_name, format_const, format_quantity,
                                   string_literal)
from addt_dsl.registry import ENVIRONMENTS, FAULTS, GEOMETRIES, ParamSpec
from addt_dsl.sweep import expand
from addt_dsl.vehicles import DEFAULT_MASS_KG, DEFAULT_WHEELBASE_M, VEHICLES

INDENT = "  "


class _Printer:
    def __init__(self, plan: ScenarioPlan, verbatim: set[tuple[str, int]]):
        self.plan = plan
        self.exprs = ExprPrinter({p.name: dim_of_name(p.dimension) for p in plan.params})
        self.verbatim = verbatim  # (section, index) whose user text is printed as written
        self.lines: list[str] = []

    def emit(self, depth: int, text: str = "") -> None:
        self.lines.append(INDENT * depth + text if text else "")

    def setting(self, spec: ParamSpec | None, key: str, value) -> str:
        """`key value`, the value printed as its ParamSpec says."""
        if spec is None:
            raise PrinterError(f"no setting {key!r} in the registry")
        if isinstance(value, str):
            if spec.kind == "string":
                return f"{key} {string_literal(value)}"
            if not re.fullmatch(r"[A-Za-z_]\w*", value):
                raise PrinterError(f"{key} {value!r} is not a word")
            return f"{key} {value}"
        dim = spec.dim if spec.dim is not None else units.DIMENSIONLESS
        if isinstance(value, list):
            return f"{key} [{', '.join(self.exprs.value(v, dim) for v in value)}]"
        return f"{key} {self.exprs.value(value, dim)}"

    def settings(self, specs, values: dict) -> str:
        table = {s.name: s for s in specs}
        return " ".join(self.setting(table.get(k), k, v) for k, v in values.items())


def _join(*parts: str) -> str:
    return " ".join(p for p in parts if p)


# -- header

HEADER = (  # keyword, plan field, how to print
    ("description", "description", lambda v: string_literal(v) if v else None),
    ("duration", "duration_s", lambda v: format_quantity(v, units.TIME)),
    ("step", "step_s", lambda v: format_quantity(v, units.TIME)),
    ("seed", "seed", lambda v: str(int(v))),
    ("run_seed", "run_seed", lambda v: None if v is None else str(int(v))),
)


def _header(pr: _Printer) -> None:
    for keyword, field, fmt in HEADER:
        text = fmt(getattr(pr.plan, field))
        if text is not None:
            pr.emit(1, f"{keyword} {text}")


# -- roads

LANES = (("right", "right_lanes"), ("left", "left_lanes"), ("width", "lane_width_m"), ("offset", "lane_offset_m"))


def _const_setting(pr: _Printer, spec_owner: str, key: str, value: float) -> str:
    spec = {s.name: s for s in GEOMETRIES.get(spec_owner).params}[key]
    return pr.setting(spec, key, E.Num(value=float(value)))


def _roads(pr: _Printer) -> None:
    for road in pr.plan.roads:
        pr.emit(0)
        if road.source == "xodr":
            rid = road.xodr_road_id
            if rid is not None and not re.fullmatch(r"\d+", rid):
                raise PrinterError(f"xodr road id {rid!r} is not a number")
            pr.emit(1, _join(f"road {road.name} import {string_literal(_xodr_name(road))}",
                             f"road {rid}" if rid is not None else ""))
            continue
        pr.emit(1, f"road {road.name} {{")
        for seg in road.segments:  # each geometry element says which settings make its segment
            settings = GEOMETRIES.get(seg.kind).settings_of(seg)
            pr.emit(2, _join(seg.kind, *(_const_setting(pr, seg.kind, k, v) for k, v in settings.items())))
        defaults = {s.name: s.default for s in GEOMETRIES.get("lanes").params}
        lanes = [_const_setting(pr, "lanes", k, getattr(road, f)) for k, f in LANES if getattr(road, f) != defaults[k]]
        if lanes:
            pr.emit(2, _join("lanes", *lanes))
        pr.emit(1, "}")


def _xodr_name(road: RoadPlan) -> str:
    return Path(road.xodr_file or f"{road.name}.xodr").name


def side_files(plan: ScenarioPlan) -> dict[str, str]:
    """Files a printed plan imports (embedded OpenDRIVE text), by the name it uses."""
    return {_xodr_name(r): r.xodr_text or "" for r in plan.roads if r.source == "xodr"}


# -- parameters and assumptions

def _params(pr: _Printer) -> None:
    if pr.plan.params:
        pr.emit(0)
    for p in pr.plan.params:
        pr.emit(1, _param_line(p))
    for i, a in enumerate(pr.plan.assumptions):
        body = _user_body(a.text) if ("assume", i) in pr.verbatim else None
        pr.emit(1, _join("assume", f"{a.name}:" if a.name else "", body or pr.exprs.formula(a.expr)))


def _param_line(p: ParamPlan) -> str:
    dim = dim_of_name(p.dimension)
    parts = [f"param {p.name} = {format_const(p.default, dim)}"]
    if p.choices:
        parts.append(f"in [{', '.join(format_const(c, dim) for c in p.choices)}]")
    elif p.low is not None or p.high is not None:
        if p.low is None or p.high is None:
            raise PrinterError(f"half-open range of {p.name!r} has no surface syntax")
        parts.append(f"in [{format_const(p.low, dim)}, {format_const(p.high, dim)}]")
    # Three or more values are a choice by themselves; two read back as a range without `dist choice`.
    implied_dist = "choice" if len(p.choices) > 2 else "uniform"
    if p.distribution != implied_dist:
        parts.append(f"dist {p.distribution}")
    if p.mean is not None:
        parts.append(f"mean {format_const(p.mean, dim)}")
    if p.sd is not None:
        parts.append(f"sd {format_const(p.sd, dim)}")
    if p.bins:
        parts.append(f"bins [{', '.join(format_const(b, dim) for b in p.bins)}]")
    if p.weights:
        parts.append(f"weights [{', '.join(format_const(w, units.DIMENSIONLESS) for w in p.weights)}]")
    if p.integer and p.distribution != "poisson":  # a Poisson parameter counts: integer by itself
        parts.append("integer true")
    return " ".join(parts)


# -- actors

VEHICLE_DEFAULTS = {  # what the compiler fills in when a setting is left out
    "length": lambda a: _vehicle_size(a.vehicle)[0], "width": lambda a: _vehicle_size(a.vehicle)[1],
    "height": lambda a: VEHICLES[a.vehicle].height_m if a.height_m is not None else None,
    "mass": lambda a: DEFAULT_MASS_KG, "wheelbase": lambda a: DEFAULT_WHEELBASE_M,
}
ACTOR_EXPRS = (("goal", "goal_s", units.LENGTH), ("mu", "mu", units.DIMENSIONLESS),  # optional, may use parameters
               ("offset", "offset", units.LENGTH), ("yaw", "yaw", units.ANGLE))
ACTOR_FLAGS = (("at_red run", "ignore_lights"), ("direction reverse", "reverse"),
               ("at_road_end stop", "stop_at_road_end"))  # printed when the plan's flag is set
ACTOR_FLOATS = (("length", "length_m", units.LENGTH), ("width", "width_m", units.LENGTH),
                ("height", "height_m", units.LENGTH),
                ("mass", "mass_kg", units.MASS), ("wheelbase", "wheelbase_m", units.LENGTH))


def _vehicle_size(kind: str) -> tuple[float, float]:
    return VEHICLES[kind].length_m, VEHICLES[kind].width_m


def _actors(pr: _Printer) -> None:
    for actor in pr.plan.actors():
        pr.emit(0)
        _actor(pr, actor, actor is pr.plan.ego)


_PLAIN_STOP = re.compile(r"[0-9]+|[A-Za-z_][A-Za-z0-9_]*")


def format_route_stop(road_id: str) -> str:
    """A road id of a route as the grammar reads it: a whole number or a name as is,
    anything else in quotes."""
    if _PLAIN_STOP.fullmatch(road_id):
        return road_id
    return '"' + road_id.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _actor(pr: _Printer, a: ActorPlan, is_ego: bool) -> None:
    ex = pr.exprs
    head = "ego" if is_ego else f"agent {a.name}"
    parts = [f"{head} {a.vehicle} on {a.road}"]
    if a.route:
        parts.append("route " + " -> ".join(format_route_stop(r) for r in a.route))
    parts += [f"lane {ex.value(a.lane, units.DIMENSIONLESS)}",
              f"at {ex.value(a.s, units.LENGTH)}", f"speed {ex.value(a.speed, units.SPEED)}"]
    for key, field, dim in ACTOR_EXPRS:
        value = getattr(a, field, None)
        if value is not None:
            parts.append(f"{key} {ex.value(value, dim)}")
    for key, field, dim in ACTOR_FLOATS:
        value = getattr(a, field)
        if value != VEHICLE_DEFAULTS[key](a):
            parts.append(f"{key} {format_quantity(value, dim)}")
    parts += [text for text, field in ACTOR_FLAGS if getattr(a, field)]
    clauses = ([a.stack] if a.stack is not None else []) + list(a.sensors) + list(a.behaviors)
    if not clauses and not a.triggers:
        pr.emit(1, " ".join(parts))
        return
    pr.emit(1, " ".join(parts) + " {")
    for c in clauses:
        pr.emit(2, _clause(pr, c))
    for tr in a.triggers:
        _step(pr, tr, 2, in_group=False)
    pr.emit(1, "}")


def _step(pr: _Printer, tr: TriggerPlan, depth: int, in_group: bool) -> None:
    """A step of an agent's script: `[at T] [after T] [when F then] action`, the action a
    behaviour or a `sequence`/`parallel` block of steps."""
    starts = _starts(pr, tr, "then")
    if (tr.clause is None) == (tr.group is None):
        raise PrinterError("a step starts one behaviour or one group")
    if not starts and tr.clause is not None and not in_group:
        raise PrinterError("a step without a start condition outside a group reads back as a behaviour")
    if tr.label is not None:  # `brake_hard: at 3 s ...`
        if not starts and tr.clause is not None:
            raise PrinterError("a named step needs a start condition (`name: after 0 s behavior ...`)")
        starts = _join(f"{tr.label}:", starts)
    if tr.clause is not None:
        pr.emit(depth, _join(starts, _clause(pr, tr.clause)))
        return
    if not tr.group.steps:
        raise PrinterError(f"an empty `{tr.group.mode}` block has no surface syntax")
    pr.emit(depth, _join(starts, tr.group.mode, "{"))
    for sub in tr.group.steps:
        _step(pr, sub, depth + 1, in_group=True)
    pr.emit(depth, "}")


def _starts(pr: _Printer, tr: TriggerPlan, then: str) -> str:
    """`[at T] [after T] [when [EDGE] F [for D] [delayed D] then]`."""
    ex = pr.exprs
    return _join(f"at {ex.value(tr.at_s, units.TIME)}" if tr.at_s is not None else "",
                 f"after {ex.value(tr.after_s, units.TIME)}" if tr.after_s is not None else "",
                 _join(f"when {tr.edge + ' ' if tr.edge else ''}{ex.formula(tr.condition)}{_hold(pr, tr)}", then)
                 if tr.condition is not None else "")


def _end(pr: _Printer) -> None:
    """`end when ...`: the condition that ends the run."""
    end = pr.plan.end
    if end is None:
        return
    if end.clause is not None or end.group is not None or end.label is not None:
        raise PrinterError("the run's end starts no behaviour")
    starts = _starts(pr, end, "")
    if not starts:
        raise PrinterError("an `end` needs a start condition")
    pr.emit(0)
    pr.emit(1, f"end {starts}")


def _hold(pr: _Printer, tr: TriggerPlan) -> str:
    hold = f" for {pr.exprs.value(tr.hold_s, units.TIME)}" if tr.hold_s is not None else ""
    delay = f" delayed {pr.exprs.value(tr.delay_s, units.TIME)}" if tr.delay_s is not None else ""
    repeat = f" repeat {tr.repeat}" if tr.repeat is not None else ""
    return hold + delay + repeat


def _clause(pr: _Printer, c: ClausePlan) -> str:
    if c.keyword == "light":  # a traffic light's state change (`lights { }`)
        return _join("light", c.name, pr.settings(LIGHT_CLAUSE_SPECS, c.settings))
    cls = CLAUSE_TABLES.get(c.keyword, {}).get(c.name)
    if cls is None:
        raise PrinterError(f"unknown {c.keyword} {c.name!r}")
    return _join(c.keyword, c.name, pr.settings(cls.params, c.settings))


# -- traffic lights

def _lights(pr: _Printer) -> None:
    plan = pr.plan
    if not (plan.signals or plan.controllers or plan.light_steps):
        return
    ex = pr.exprs
    pr.emit(0)
    pr.emit(1, "lights {")
    for sig in plan.signals:
        pr.emit(2, _join(f"signal {sig.name} road {sig.road} at {format_quantity(sig.s_m, units.LENGTH)}",
                         f"lane {sig.lanes[0]}" if sig.lanes else ""))
    defaults = {s.name: s.default for s in CONTROLLER_SPECS}
    for c in plan.controllers:
        times = [f"{key} {ex.value(getattr(c, key + '_s'), units.TIME)}" for key in ("green", "yellow", "red", "offset")
                 if getattr(c, key + "_s") != E.Num(value=float(defaults[key]))]
        pr.emit(2, _join(f"controller {c.name} road {c.road}",
                         "signals [" + ", ".join(_signal_id(i) for i in c.signals) + "]", *times))
    for tr in plan.light_steps:  # a bare `light` line reads back as a step at time 0
        _step(pr, tr, 2, in_group=True)
    pr.emit(1, "}")


def _signal_id(sid: str) -> str:
    """A signal id as `signals [...]` reads it: a whole number, a name, or a string."""
    if re.fullmatch(r"-?[0-9]+", sid) and str(int(sid)) == sid:
        return sid
    return sid if re.fullmatch(r"[A-Za-z_]\w*", sid) else string_literal(sid)


# -- faults

def _faults(pr: _Printer) -> None:
    if not pr.plan.faults:
        return
    pr.emit(0)
    pr.emit(1, "faults {")
    for f in pr.plan.faults:
        pr.emit(2, _fault_line(pr, f))
    pr.emit(1, "}")


def _timing(pr: _Printer, f: FaultPlan) -> str:
    ex = pr.exprs
    if f.opens is not None:
        return _fault_opening(pr, f)
    if f.end_s is None:
        return "" if f.start_s == E.Num(value=0.0) else f"from {ex.value(f.start_s, units.TIME)}"
    if f.end_s == f.start_s:
        return f"at {ex.value(f.start_s, units.TIME)}"
    return f"during [{ex.value(f.start_s, units.TIME)}, {ex.value(f.end_s, units.TIME)}]"


def _fault_opening(pr: _Printer, f: FaultPlan) -> str:
    """`when [EDGE] F [delayed D] [for W]`: the window counts from where its start fires."""
    tr, ex = f.opens, pr.exprs
    if tr.condition is None or f.start_s != E.Num(value=0.0) or any(
            v is not None for v in (tr.at_s, tr.after_s, tr.hold_s, tr.repeat, tr.clause, tr.group, tr.label)):
        raise PrinterError("a fault window opens on a `when` condition alone, at the instant it fires")
    delay = f" delayed {ex.value(tr.delay_s, units.TIME)}" if tr.delay_s is not None else ""
    length = f" for {ex.value(f.end_s, units.TIME)}" if f.end_s is not None else ""
    return f"when {tr.edge + ' ' if tr.edge else ''}{ex.formula(tr.condition)}{delay}{length}"


def _fault_line(pr: _Printer, f: FaultPlan) -> str:
    cls = FAULTS.get(f.kind)
    if cls is None:
        raise PrinterError(f"unknown fault kind {f.kind!r}")
    seed = f"seed {int(f.seed)}" if f.seed is not None else ""
    return _join(_timing(pr, f), f.kind, f.target, pr.settings(cls.params, f.settings), seed)


# -- oracles

def _builtin_clause(plan: ScenarioPlan, o: OraclePlan) -> tuple[str, str] | None:
    """(built-in oracle text, its default name) when the formula is exactly what that
    built-in lowers to: `no collision [with X]`, `reach goal [within T]`."""
    if o.formula == NO_CLAUSES["collision"]("ego", None):
        return "no collision", "no_collision"
    for word in EGO_ONLY:
        if o.formula == NO_CLAUSES[word]("ego", None):
            return f"no {word}", f"no_{word}"
    for signal in E.signals_used(o.formula):
        if signal.startswith("distance(ego,"):
            other = signal[len("distance(ego,"):-1]
            if o.formula == NO_CLAUSES["collision"]("ego", other):
                return f"no collision with {other}", f"no_collision_with_{other}"
    goal, f = plan.ego.goal_s, o.formula
    if goal is not None and isinstance(f, E.Temporal) and f == reach_goal_formula(goal, f.hi_s):
        if f.hi_s is None or isinstance(f.hi_s, float):
            within = "" if f.hi_s is None else f" within {format_quantity(f.hi_s, units.TIME)}"
        else:  # over parameters: `reach goal within t_max`
            exprs = ExprPrinter({p.name: dim_of_name(p.dimension) for p in plan.params})
            within = f" within {exprs.value(f.hi_s, units.TIME)}"
        return "reach goal" + within, "reach_goal"
    return None


def _shown_oracles(plan: ScenarioPlan) -> list[int]:
    """Indices of the oracles the source states. A goal on the ego adds `reach_goal`
    (last, hard, no time limit) unless an oracle is named `reach_goal` or states `reach
    goal`: that added oracle is left out when the rest of the source does not state one."""
    indices = list(range(len(plan.oracles)))
    if plan.ego.goal_s is None:
        return indices

    def states_goal(o: OraclePlan) -> bool:
        clause = _builtin_clause(plan, o)
        return o.name == "reach_goal" or (clause is not None and clause[1] == "reach_goal")

    implied = OraclePlan(name="reach_goal", severity="hard", formula=reach_goal_formula(plan.ego.goal_s))
    last = plan.oracles[-1] if plan.oracles else None
    if last is not None and (last.name, last.severity, last.formula) == (implied.name, implied.severity,
                                                                        implied.formula) \
            and not any(states_goal(o) for o in plan.oracles[:-1]):
        return indices[:-1]
    if not any(states_goal(o) for o in plan.oracles):
        raise PrinterError("the ego has a goal but no oracle named reach_goal: its source would add one")
    return indices


_TEXT_HEAD = re.compile(r"\s*(?:(hard|warn)\s+)?(?:([A-Za-z_]\w*)\s*:(?!=))?\s*(?P<body>.*)$", re.S)


def _user_body(text: str) -> str | None:
    """The formula part of a user's oracle/assumption text, if it is one clean line."""
    if not text or "\n" in text or "#" in text or "\\" in text:
        return None
    body = _TEXT_HEAD.match(text).group("body").strip()
    return body or None


def _oracles(pr: _Printer) -> None:
    shown = [(i, pr.plan.oracles[i]) for i in _shown_oracles(pr.plan)]
    if not shown:
        return
    pr.emit(0)
    pr.emit(1, "expect {")
    for i, o in shown:
        pr.emit(2, _oracle_line(pr, i, o))
    pr.emit(1, "}")


def _oracle_line(pr: _Printer, index: int, o: OraclePlan) -> str:
    severity = "warn" if o.severity == "warn" else ""
    builtin = _builtin_clause(pr.plan, o)
    if builtin is not None:
        body, default_name = builtin
        return _join(severity, "" if o.name == default_name else f"{o.name}:", body)
    body = _user_body(o.text) if ("oracle", index) in pr.verbatim else None
    if body is not None and body.startswith("no "):
        body = None
    return _join(severity, f"{o.name}:", body or pr.exprs.formula(o.formula))


# -- sweep

def _sweep(pr: _Printer) -> None:
    sw = pr.plan.sweep
    items = []
    dims = {p.name: dim_of_name(p.dimension) for p in pr.plan.params}
    for axis in sw.grid:
        if axis.param not in dims:
            raise PrinterError(f"grid over unknown parameter {axis.param!r}")
        items.append(f"grid {axis.param} in [{', '.join(format_const(v, dims[axis.param]) for v in axis.values)}]")
    for axis in sw.cases:
        unknown = [n for n in axis.params if n not in dims]
        if unknown:
            raise PrinterError(f"cases over unknown parameter {unknown[0]!r}")
        items.append("cases " + ", ".join(
            f"{n} in [{', '.join(format_const(row[k], dims[n]) for row in axis.rows)}]"
            for k, n in enumerate(axis.params)))
    if sw.sampler is not None:
        items.append(_join(f"{sw.sampler.kind} {sw.sampler.count}",
                           f"seed {sw.sampler.seed}" if sw.sampler.seed else ""))
    if sw.repeat != 1:
        items.append(f"repeat {sw.repeat}")
    if sw.seed:
        items.append(f"seed {sw.seed}")
    if sw.max_rejections != SweepPlan().max_rejections:
        items.append(f"max_rejections {sw.max_rejections}")
    if not items:
        return
    pr.emit(0)
    pr.emit(1, "sweep {")
    for item in items:
        pr.emit(2, item)
    pr.emit(1, "}")


def _environment(pr: _Printer) -> None:
    if not (pr.plan.environment or pr.plan.environment_steps):
        return
    pr.emit(0)
    pr.emit(1, "environment {")
    for c in pr.plan.environment:
        pr.emit(2, _env_model(pr, c))
    for tr in pr.plan.environment_steps:  # `at 10 s fog visibility 20 m`
        starts = _starts(pr, tr, "then")
        if not starts or tr.clause is None or tr.group is not None or tr.label is not None:
            raise PrinterError("an environment change is one model's settings from a start on")
        pr.emit(2, _join(starts, _env_model(pr, tr.clause)))
    pr.emit(1, "}")


def _variables(pr: _Printer) -> None:
    if not (pr.plan.variables or pr.plan.variable_steps):
        return
    pr.emit(0)
    pr.emit(1, "variables {")
    for v in pr.plan.variables:
        pr.emit(2, f"{v.name} = {pr.exprs.value(E.Num(value=v.value), units.DIMENSIONLESS)}")
    for tr in pr.plan.variable_steps:  # `at 3 s set phase 1`
        starts = _starts(pr, tr, "then")
        if not starts or tr.clause is None or tr.clause.keyword != "set" or tr.group is not None \
                or tr.label is not None:
            raise PrinterError("a variable step sets one variable from a start on")
        pr.emit(2, _join(starts, f"set {tr.clause.name}",
                         pr.exprs.value(tr.clause.settings["value"], units.DIMENSIONLESS)))
    pr.emit(1, "}")


def _env_model(pr: _Printer, c: ClausePlan) -> str:
    cls = ENVIRONMENTS.get(c.name)
    if cls is None:
        raise PrinterError(f"unknown environment model {c.name!r}")
    return _join(c.name, pr.settings(cls.params, c.settings))


SECTIONS: tuple[Callable[[_Printer], None], ...] = (_header, _roads, _params, _actors, _lights, _environment,
                                                    _variables, _end, _faults, _oracles, _sweep)


# ---------------------------------------------------------------- entry points

def _render(plan: ScenarioPlan, verbatim: set, comment: str) -> str:
    if not re.fullmatch(r"[A-Za-z_]\w*", plan.name):
        raise PrinterError(f"scenario name {plan.name!r} is not a name")
    pr = _Printer(plan, verbatim)
    for line in comment.splitlines():
        pr.lines.append(f"# {line}".rstrip())
    pr.lines.append(f"scenario {plan.name} {{")
    for section in SECTIONS:
        section(pr)
    pr.lines.append("}")
    return "\n".join(pr.lines) + "\n"


def print_plan(plan: ScenarioPlan, comment: str = "", keep_user_text: bool = True) -> str:
    """The plan as `.addt` source.

    With `keep_user_text`, oracles and assumptions are printed as the user wrote them
    (their `text`) wherever that compiles back to the same formula, checked by compiling
    the result once; everything else is printed from the plan's trees.
    """
    if not keep_user_text:
        return _render(plan, set(), comment)
    candidates = {("oracle", i) for i, o in enumerate(plan.oracles) if _user_body(o.text)}
    candidates |= {("assume", i) for i, a in enumerate(plan.assumptions) if _user_body(a.text)}
    if not candidates:
        return _render(plan, set(), comment)
    text = _render(plan, candidates, comment)
    got = _compile_plan(text, plan)
    if got is None:
        return _render(plan, set(), comment)
    keep = {("oracle", i) for i, (a, b) in enumerate(zip(plan.oracles, got.oracles))
            if (a.name, a.severity, a.formula) == (b.name, b.severity, b.formula)}
    keep |= {("assume", i) for i, (a, b) in enumerate(zip(plan.assumptions, got.assumptions)) if a.expr == b.expr}
    if len(got.oracles) != len(plan.oracles) or len(got.assumptions) != len(plan.assumptions):
        keep = set()
    keep &= candidates
    return text if keep == candidates else _render(plan, keep, comment)


def _compile_plan(text: str, plan: ScenarioPlan) -> ScenarioPlan | None:
    files = side_files(plan)
    if not files:
        return compile_source(text, path="<printed>").plan
    with tempfile.TemporaryDirectory() as tmp:
        for name, body in files.items():
            (Path(tmp) / name).write_text(body)
        return compile_source(text, path="<printed>", base_dir=tmp).plan


def _literal(value):
    if isinstance(value, str):
        return value
    if isinstance(value, list):
        return [E.Num(value=float(v)) for v in value]
    return E.Num(value=float(value))


def _whole_int_settings(f: ConcreteFault) -> ConcreteFault:
    """Int settings fed by a continuous parameter (`count k`, k = 1.4) are truncated the
    way the fault kinds read them (`int(...)`), so the pinned literal compiles."""
    cls = FAULTS.get(f.kind)
    ints = {p.name for p in (cls.params if cls else ()) if p.kind == "int"}
    fixed = {k: float(int(v)) for k, v in f.settings.items()
             if k in ints and isinstance(v, float) and math.isfinite(v) and v != int(v)}
    return f.model_copy(update={"settings": {**f.settings, **fixed}}) if fixed else f


def pinned_fault_plan(f: ConcreteFault, source: str = "") -> FaultPlan:
    """A concrete fault as the plan entry that reproduces it exactly (its seed included)."""
    start = E.Num(value=float(f.start_s))
    end = None if f.end_s is None else (start if f.end_s == f.start_s else E.Num(value=float(f.end_s)))
    return FaultPlan(kind=f.kind, target=f.target, start_s=start, end_s=end,
                     settings={k: _literal(v) for k, v in f.settings.items()}, seed=int(f.seed), source=source,
                     opens=f.opens)


def pin_spec(spec: RunSpec) -> RunSpec:
    """The RunSpec of the plan that runs exactly `spec` and nothing else: parameters
    fixed at their values, no sweep, the concrete faults (renumbered) with their seeds,
    the run seed pinned. Same run: the trace is bit for bit the one of `spec`
    (fault events carry the renumbered index)."""
    plan = spec.plan
    sources = {i: f.source for i, f in enumerate(plan.faults)}
    concrete = [_whole_int_settings(f).model_copy(update={"index": i}) for i, f in enumerate(spec.faults)]
    faults = [pinned_fault_plan(f, sources.get(orig.index, "")) for f, orig in zip(concrete, spec.faults)]
    pinned_plan = plan.model_copy(update={"params": [], "faults": faults, "sweep": SweepPlan(),
                                          "run_seed": int(spec.seed)})
    # Parameters that only fed the (now literal) faults or the sweep are dropped.
    used = params_referenced(pinned_plan)
    params = [ParamPlan(name=p.name, dimension=p.dimension, default=float(spec.params.get(p.name, p.default)))
              for p in plan.params if p.name in used]
    pinned_plan = pinned_plan.model_copy(update={"params": params})
    return RunSpec(plan=pinned_plan, params={p.name: p.default for p in params}, seed=int(spec.seed),
                   faults=concrete, run_id=spec.run_id)


def params_referenced(plan: ScenarioPlan) -> set[str]:
    """Names of the parameters any expression of the plan refers to."""
    found: set[str] = set()

    def visit(node) -> None:
        if isinstance(node, dict):
            if node.get("kind") == "param" and isinstance(node.get("name"), str):
                found.add(node["name"])
            for v in node.values():
                visit(v)
        elif isinstance(node, list):
            for v in node:
                visit(v)

    visit(plan.model_dump(mode="json", exclude={"params"}))
    return found


def print_spec(spec: RunSpec, comment: str | None = None) -> str:
    """One run as a pinned `.addt` file: `addtc` on it replays exactly this run."""
    if comment is None:
        origin = spec.plan.source_file or "<unknown>"
        comment = (f"Pinned run of {origin}" + (f" ({spec.run_id})" if spec.run_id else "")
                   + f"\nkey {spec.key()}; replay: addtc FILE")
    return print_plan(pin_spec(spec).plan, comment)


# ---------------------------------------------------------------- identity

def _strip_provenance(data: dict) -> dict:
    plan = data["plan"] if "plan" in data else data
    plan["source_file"] = ""
    for f in plan.get("faults", []):
        f["source"] = ""
    for o in plan.get("oracles", []):
        o["text"] = ""
    for a in plan.get("assumptions", []):
        a["text"] = ""
    for r in plan.get("roads", []):
        if r.get("xodr_file") is not None:
            r["xodr_file"] = Path(r["xodr_file"]).name
    data.pop("run_id", None)
    return data


def semantic_key(obj: RunSpec | ScenarioPlan) -> str:
    """Like `RunSpec.key()`, without provenance: the file name, fault source lines and
    the oracles' and assumptions' source text. Equal semantic keys, same run."""
    data = _strip_provenance(obj.model_dump(mode="json"))
    text = json.dumps(data, sort_keys=True, separators=(",", ":")).encode()
    return hashlib.sha256(text).hexdigest()[:20]


def check_spec(spec: RunSpec, limits: Limits = DEFAULT_LIMITS) -> None:
    """A RunSpec read from a file (`addtc shrink --run-key`, a results store) has met no
    compiler: printed pinned and compiled again, it meets the compiler's checks and limits
    (a duration of 1e308 s, a step of 0, 5000 agents: E0301, E0701) before anything runs it.
    Raises ValueError with the diagnostics."""
    try:
        pinned = pin_spec(spec).plan
        text = print_plan(pinned, keep_user_text=False)
    except (PrinterError, ValueError, TypeError) as exc:  # pydantic's ValidationError is a ValueError
        raise ValueError(f"it cannot be written as a scenario: {(str(exc).splitlines() or [''])[0]}") from None
    with tempfile.TemporaryDirectory() as tmp:
        for name, body in side_files(pinned).items():
            (Path(tmp) / name).write_text(body)
        compile_pinned(text, path="<the run's scenario>", base_dir=tmp, limits=limits)


def compile_pinned(text: str | bytes, path: str = "<pinned>", base_dir: str | Path = ".",
                   limits: Limits = DEFAULT_LIMITS) -> RunSpec:
    """Compile a pinned file and return its one run (raises ValueError otherwise)."""
    result = compile_source(text, path=path, base_dir=base_dir, limits=limits)
    if not result.ok:
        raise ValueError("pinned source does not compile:\n" + render_text(result.diagnostics, result.sources))
    specs = expand(result.plan).specs
    if len(specs) != 1:
        raise ValueError(f"pinned source expands to {len(specs)} runs, not 1")
    return specs[0]
