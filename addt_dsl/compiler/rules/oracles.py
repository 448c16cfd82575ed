"""Oracles in `expect` blocks: built-ins (`no collision`, `stay in lane`, `reach goal`,
`min`/`max SIGNAL`) lowered to STL formulas, and formulas whose windows end within the scenario."""

from __future__ import annotations

from dataclasses import dataclass

from addt_dsl import expr as E
from addt_dsl import plan as P
from addt_dsl import units
from addt_dsl.compiler import ast
from addt_dsl.compiler.context import (Context, check_settings, check_time, const_value, fmt, int_const, range_text,
                                       suggest, text_of)
from addt_dsl.compiler.exprs import comparisons, value_range
from addt_dsl.diagnostics import Span
from addt_dsl.registry import SIGNALS, ParamSpec
from addt_dsl.sweep import known_assignments


def _always(formula):
    return E.Temporal(op="always", arg=formula)


def _collision_with(other: str):
    # Box-to-box clearance between two actors is not a trace signal; use the ego's
    # clearance while the other actor is its nearest neighbour (distance as a guard).
    return _always(E.Binary(op="or", left=E.Binary(
        op=">", left=E.Signal(name="clearance(ego)"), right=E.Num(value=0.0)), right=E.Binary(
        op=">", left=E.Signal(name=f"distance(ego,{other})"), right=E.Num(value=15.0))))


BUILTIN_NAMES = ("no collision", "no red_light", "no stop_sign", "stay in lane", "reach goal", "min SIGNAL",
                 "max SIGNAL")

# `no collision [with X]` → formula; the printer recognises built-ins through this table.
NO_CLAUSES = {
    "collision": lambda actor, other: (
        _always(E.Binary(op=">", left=E.Signal(name=f"clearance({actor})"), right=E.Num(value=0.0)))
        if other is None else _collision_with(other)),
    # The ego never crosses the stop line of a red light that governs its lane (the
    # margin signal `red_light`, runtime/lights.py).
    "red_light": lambda actor, other: _always(E.Binary(
        op=">=", left=E.Signal(name=f"red_light({actor})"), right=E.Num(value=0.0))),
    # The ego stops for every stop sign of the map that governs its lane before crossing its
    # line (the margin signal `stop_sign`, runtime/signs.py).
    "stop_sign": lambda actor, other: _always(E.Binary(
        op=">=", left=E.Signal(name=f"stop_sign({actor})"), right=E.Num(value=0.0))),
}
EGO_ONLY = ("red_light", "stop_sign")  # `no WORD` clauses that judge the ego and take no `with`


def reach_goal_formula(goal, within_s: float | E.Expr | None = None):
    """`reach goal [within T]`, and the oracle a goal on the ego adds by itself."""
    return E.Temporal(op="eventually", lo_s=0.0, hi_s=within_s,
                      arg=E.Binary(op=">=", left=E.Signal(name="s(ego)"), right=goal))


def _builtin(ctx: Context, b: ast.Builtin) -> tuple[E.Expr, str] | None:
    """Lower a built-in oracle to (STL formula, default name)."""
    if b.kind == "no":
        if b.word not in NO_CLAUSES:
            ctx.sink.error("E0106", f"unknown built-in oracle 'no {b.word}'", b.word_span,
                           "built-ins: " + ", ".join(BUILTIN_NAMES))
            return None
        if b.word in EGO_ONLY:
            if b.actor is not None:
                ctx.sink.error("E0204", f"`no {b.word}` judges the ego; it takes no `with`", b.actor_span,
                               f"for an agent write `always {b.word}({b.actor}) >= 0 m`")
                return None
            return NO_CLAUSES[b.word]("ego", None), f"no_{b.word}"
        if b.actor is None:
            return NO_CLAUSES["collision"]("ego", None), "no_collision"
        if b.actor not in ctx.actors_ast or b.actor == "ego":
            ctx.sink.error("E0101", f"unknown agent '{b.actor}'", b.actor_span,
                           *suggest(b.actor, [a for a in ctx.actors_ast if a != "ego"]))
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
            hi = const_value(hi_e)
            if hi is None:  # over parameters: checked as a window for every run of the sweep
                formula = reach_goal_formula(ego.goal_s, hi_e)
                return (formula, "reach_goal") if _check_param_window(ctx, formula, b.value.span) else None
            if not check_time(ctx, hi_e, b.value.span, "the time limit"):
                return None
        return reach_goal_formula(ego.goal_s, hi), "reach_goal"
    return _bound(ctx, b)


def _stay_in_lane(ctx: Context, b: ast.Builtin):
    vals = check_settings(ctx, b.settings, (ParamSpec("tolerance", units.LENGTH, default=0.0, low=0.0, high=10.0,
                                                      doc="how far the body may cross the lane border"),),
                          "`stay in lane`", b.span)
    ego = ctx.actors.get("ego")
    if ego is None:
        return None
    tol = const_value(vals["tolerance"]) if "tolerance" in vals else 0.0
    if tol is None:
        ctx.sink.error("E0204", "the tolerance must be a constant", b.span)
        return None
    info = ctx.road_info.get(ego.road)
    lane = int_const(ego.lane)
    if info is not None and lane is not None and lane in info.lane_width_m:
        lane_width = info.lane_width_m[lane]
    elif info is not None and info.lane_width_m:
        lane_width = min(info.lane_width_m.values())
    else:
        lane_width = 3.5
    formula = stay_in_lane_formula(lane_width, ego.width_m, tol)
    if formula is None:
        ctx.sink.error("E0301", f"the ego ({fmt(ego.width_m, units.LENGTH)} wide) does not fit in its lane "
                       f"({fmt(lane_width, units.LENGTH)})", b.span, "add a `tolerance`")
        return None
    return formula, "stay_in_lane"


def stay_in_lane_formula(lane_width_m: float, ego_width_m: float, tolerance_m: float = 0.0):
    """`stay in lane`: the body inside the lane, |offset of the centre| + half the width <=
    half the lane (+ the tolerance); None when the ego does not fit."""
    margin = 0.5 * (lane_width_m - ego_width_m) + tolerance_m
    if margin <= 0:
        return None
    return _always(E.Binary(op="<=", left=E.Call(fn="abs", args=(E.Signal(name="lane_offset(ego)"),)),
                            right=E.Num(value=margin)))


def _bound(ctx: Context, b: ast.Builtin):
    """`min SIGNAL [to|of X] V` → always SIGNAL >= V; `max ...` → always |SIGNAL| <= V."""
    cls = SIGNALS.get(b.word)
    if cls is None:
        ctx.sink.error("E0101", f"unknown signal '{b.word}'", b.word_span, *suggest(b.word, SIGNALS.names()),
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
        ctx.sink.error("E0101", f"unknown {kind} '{b.actor}'", b.actor_span, *suggest(b.actor, pool),
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


@dataclass(frozen=True)
class Oracles:
    oracles: list[P.OraclePlan]


def rule_oracles(ctx: Context) -> Oracles:
    out = Oracles([])
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
            out.oracles.append(P.OraclePlan(name=name, severity=o.severity, formula=formula,
                                            text=text_of(ctx, o.span)))
    return out


def _check_formula_windows(ctx: Context, formula, span: Span) -> bool:
    """Time windows of temporal operators must end within the scenario; a window over
    parameters is checked for every run of the sweep (`_check_param_window`)."""
    dur = ctx.duration
    for node in E.walk(formula):
        if not isinstance(node, (E.Temporal, E.Until)):
            continue
        if E.window_exprs(node):
            if not _check_param_window(ctx, node, span):
                return False
            continue
        if not isinstance(dur, float):
            continue
        for bound in (node.lo_s, node.hi_s):
            if bound is not None and bound > dur + 1e-9:
                ctx.sink.error("E0302", f"the time window reaches {fmt(bound, units.TIME)}, beyond the "
                               f"scenario's duration ({fmt(dur, units.TIME)})", span,
                               "shorten the window or lengthen `duration`")
                return False
    return True


# A window over parameters is checked per run where the sweep fixes its values (grid,
# cases, defaults: up to this many cells); a sampled one over the values its runs can draw.
WINDOW_CHECK_CELLS = 10_000
_WINDOW_CODES = {"bound": "E0301", "inverted": "E0303", "beyond": "E0302"}
_WINDOW_CAN = {"bound": "a window bound can be negative", "inverted": "the window can end before it starts",
               "beyond": "the time window can reach beyond the scenario's duration"}
_WINDOW_HINTS = {"bound": "windows are relative to the current instant: `within 5 s`, `during [2 s, 5 s]`",
                 "inverted": "a window [A, B] needs A <= B", "beyond": "shorten the window or lengthen `duration`"}


def _check_param_window(ctx: Context, node, span: Span) -> bool:
    dur = ctx.duration if isinstance(ctx.duration, float) else None
    lo, hi = node.lo_s, node.hi_s
    used = set().union(*(E.params_used(b) for b in E.window_exprs(node)))
    if not used <= {p.name for p in ctx.params}:
        return True  # a parameter with an error of its own (reported there)
    # The sweep's pieces as far as the rules have them (sweep.py reads nothing else).
    view = P.ScenarioPlan.model_construct(params=ctx.params, assumptions=ctx.assumptions, sweep=ctx.sweep)
    cells = known_assignments(view, used, WINDOW_CHECK_CELLS)
    if cells is not None:
        for values in cells:
            try:
                got = E.window_problem(_bound_at(lo, values), _bound_at(hi, values), dur)
            except (ValueError, ArithmeticError):
                got = "bound", "a window bound must be a finite time >= 0 s"
            if got is not None:
                kind, text = got
                shown = ", ".join(f"{n} = {fmt(v, ctx.param_dims.get(n))}" for n, v in values.items())
                ctx.sink.error(_WINDOW_CODES[kind], text, span, f"with {shown} (a run of the sweep)",
                               _WINDOW_HINTS[kind])
                return False
        return True
    # A sampled parameter: an error where a value the runs can draw (the ranges narrowed by
    # the constraints) makes the window invalid, as for every other value over parameters
    # (`context.check_range`). An inverted window is excluded by a constraint that orders
    # its bounds (`assume t0 <= t1` for `during [t0, t1]`).
    lo_r = (lo, lo) if isinstance(lo, float) else value_range(lo, ctx.param_ranges)
    hi_r = None if hi is None else (hi, hi) if isinstance(hi, float) else value_range(hi, ctx.param_ranges)
    if lo_r is None or (hi is not None and hi_r is None):
        return True
    ordered = hi is not None and _ordered_by_constraint(ctx, lo, hi)
    checks = [("bound", lo_r, lo_r[0] < 0.0), ("bound", hi_r, hi_r is not None and hi_r[0] < 0.0),
              ("inverted", None, hi_r is not None and hi_r[0] < lo_r[1] and not ordered),
              ("beyond", hi_r or lo_r, dur is not None and max(lo_r[1], hi_r[1] if hi_r else 0.0) > dur + 1e-9)]
    for kind, spans, can_be_bad in checks:
        if can_be_bad:
            names = ", ".join(sorted(used))
            note = f"over the ranges of {names} it spans {range_text(*spans, units.TIME)}" if spans else \
                f"over the ranges of {names} its end can come before its start"
            ctx.sink.error(_WINDOW_CODES[kind], _WINDOW_CAN[kind], span, note,
                           "narrow the parameter range, or add an `assume` that excludes those values")
            return False
    return True


def _ordered_by_constraint(ctx: Context, lo, hi) -> bool:
    """Whether a constraint states `lo <= hi` (or `<`, either way round) of these bounds."""
    lo_e = E.Num(value=lo) if isinstance(lo, float) else lo
    hi_e = E.Num(value=hi) if isinstance(hi, float) else hi
    return any((c.op in ("<", "<=") and (c.left, c.right) == (lo_e, hi_e)) or
               (c.op in (">", ">=") and (c.left, c.right) == (hi_e, lo_e))
               for c in comparisons(a.expr for a in ctx.assumptions))


def _bound_at(bound, values: dict[str, float]):
    return bound if bound is None or isinstance(bound, float) else float(E.eval_param_expr(bound, values))


def _auto_name(ctx: Context, o: ast.OracleDecl) -> str:
    return f"oracle_{o.span.line}"
