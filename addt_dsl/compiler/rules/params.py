"""Parameters: default, domain `in [lo, hi]` or choices, distribution, integer."""

from __future__ import annotations

import math
from dataclasses import dataclass

from addt_dsl import plan as P
from addt_dsl import units
from addt_dsl.compiler import ast
from addt_dsl.compiler.context import INT_EPS, Context, const_value, fmt, lower_list, range_text, suggest
from addt_dsl.compiler.exprs import ExprLowering, Scope
from addt_dsl.distributions import DISTRIBUTIONS, MAX_POISSON_MEAN
from addt_dsl.limits import MAX_ABS_NUMBER

PARAM_SETTINGS = ("dist", "mean", "sd", "bins", "weights", "integer")
DIST_SETTINGS = ("mean", "sd", "bins", "weights")  # each distribution's own (distributions.py)


@dataclass(frozen=True)
class Params:
    params: list[P.ParamPlan]
    param_dims: dict  # name: Dim, also of parameters that failed after their default
    param_ranges: dict[str, tuple[float, float]]


def rule_params(ctx: Context) -> Params:
    out = Params([], {}, {})
    for d in ctx.params_ast.values():
        plan = _check_param(ctx, d, out.param_dims)
        if plan is not None:
            out.params.append(plan)
            out.param_ranges[d.name] = (plan.low, plan.high) if plan.low is not None else (plan.default,) * 2
    return out


def _check_param(ctx: Context, d: ast.ParamDecl, dims: dict) -> P.ParamPlan | None:
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
    if ty[0] != "num" or const_value(expr) is None:
        ctx.sink.error("E0204", f"the default of '{d.name}' must be a constant number", d.default.span,
                       "parameters cannot depend on other parameters; relate them with `assume`")
        return None
    dim = ty[1]
    default = const_value(expr)
    if not math.isfinite(default):
        ctx.sink.error("E0204", f"the default of '{d.name}' is not a finite number", d.default.span)
        return None
    if _absurd(ctx, [default], f"the default of '{d.name}'", d.default.span, dim):
        return None
    dims[d.name] = dim
    opts: dict[str, ast.Setting] = {}
    for st in d.settings:
        if st.key not in PARAM_SETTINGS:
            ctx.sink.error("E0104", f"parameter has no setting '{st.key}'", st.key_span,
                           *suggest(st.key, PARAM_SETTINGS),
                           f"settings of a parameter: {', '.join(PARAM_SETTINGS)}")
        elif st.key in opts:
            ctx.sink.error("E0102", f"setting '{st.key}' given twice", st.key_span)
        else:
            opts[st.key] = st
    dist = "uniform"
    if "dist" in opts:
        v = opts["dist"].value
        if isinstance(v, ast.Ref) and v.dotted in DISTRIBUTIONS:
            dist = v.dotted
        else:
            ctx.sink.error("E0204", f"`dist` is one of {', '.join(DISTRIBUTIONS)}", v.span)
            return None
    lo = hi = None
    choices: list[float] = []
    if d.domain is not None:
        if not isinstance(d.domain, ast.ListExpr):
            ctx.sink.error("E0204", f"the domain of '{d.name}' is a list: `in [low, high]` or `in [a, b, c]`",
                           d.domain.span)
            return None
        vals = lower_list(ctx, d.domain, dim, f"the domain of '{d.name}'")
        if vals is None or _absurd(ctx, vals, f"the domain of '{d.name}'", d.domain.span, dim):
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
                               f"{fmt(lo, dim)} > {fmt(hi, dim)}", d.domain.span, "write `in [low, high]`")
                return None
        if choices and not any(abs(default - c) <= 1e-12 * max(1.0, abs(c)) for c in choices):
            ctx.sink.error("E0301", f"the default of '{d.name}' ({fmt(default, dim)}) is not one of its choices",
                           d.default.span)
            return None
        if not choices and not (lo <= default <= hi):
            ctx.sink.error("E0301", f"the default of '{d.name}' ({fmt(default, dim)}) is outside its range "
                           f"{range_text(lo, hi, dim)}", d.default.span)
            return None
    elif dist == "choice":
        ctx.sink.error("E0105", f"choice parameter '{d.name}' needs its choices: `in [a, b, c]`", d.span)
        return None
    mean = sd = None
    if "mean" in opts:
        m_expr = low.lower_value(opts["mean"].value, dim, f"'mean' of '{d.name}'")
        mean = const_value(m_expr) if m_expr is not None else None
        if mean is not None and not math.isfinite(mean):
            ctx.sink.error("E0204", f"'mean' of '{d.name}' is not a finite number", opts["mean"].value.span)
            return None
        if mean is not None and _absurd(ctx, [mean], f"'mean' of '{d.name}'", opts["mean"].value.span, dim):
            return None
    if "sd" in opts:
        sd_expr = low.lower_value(opts["sd"].value, dim, f"'sd' of '{d.name}'")
        sd = const_value(sd_expr) if sd_expr is not None else None
        if sd is not None and not (sd > 0 and math.isfinite(sd)):
            ctx.sink.error("E0301", f"'sd' of '{d.name}' must be positive", opts["sd"].value.span)
            return None
        if sd is not None and _absurd(ctx, [sd], f"'sd' of '{d.name}'", opts["sd"].value.span, dim):
            return None
    spec = DISTRIBUTIONS[dist]
    for key in spec.required:
        if key not in opts:
            ctx.sink.error("E0105", f"{dist} parameter '{d.name}' needs '{key}'", d.span,
                           f"e.g. `param {d.name} = ... dist {dist} {key} ...`")
            return None
    for key in DIST_SETTINGS:
        if key in opts and key not in spec.required + spec.optional:
            takes = [name for name, other in DISTRIBUTIONS.items() if key in other.required + other.optional]
            ctx.sink.warning("W0002", f"'{key}' has no effect on a {dist} parameter", opts[key].key_span,
                             f"distributions that take it: {', '.join(takes)}")
    if spec.needs_range and (lo is None or choices):
        ctx.sink.error("E0105", f"{dist} parameter '{d.name}' needs a range: `in [low, high]`", d.span)
        return None
    bins: list[float] = []
    weights: list[float] = []
    if "weights" in opts and "weights" in spec.required + spec.optional:
        weights = _weights(ctx, opts["weights"], d.name)
        if weights is None:
            return None
    if dist == "choice" and weights and len(weights) != len(choices):
        ctx.sink.error("E0204", f"{len(weights)} weights for {len(choices)} choices of '{d.name}'",
                       opts["weights"].value.span, "give one weight per choice")
        return None
    if dist == "histogram":
        bins = _bins(ctx, opts["bins"], d.name, dim, lo, hi, len(weights))
        if bins is None:
            return None
    center = mean if mean is not None else default
    if dist == "lognormal" and not center > 0.0:
        ctx.sink.error("E0301", f"a log-normal parameter's mean must be positive ('{d.name}': {fmt(center, dim)})",
                       (opts.get("mean") or opts["dist"]).value.span)
        return None
    if dist == "poisson":
        if dim != units.DIMENSIONLESS:
            ctx.sink.error("E0204", f"a Poisson parameter counts: '{d.name}' has dimension {units.dim_name(dim)}",
                           opts["dist"].value.span)
            return None
        if not 0.0 < center <= MAX_POISSON_MEAN:
            ctx.sink.error("E0301", f"a Poisson parameter's mean must lie in (0, {MAX_POISSON_MEAN:g}] "
                           f"('{d.name}': {center:g})", (opts.get("mean") or opts["dist"]).value.span)
            return None
    integer = False
    if "integer" in opts:
        v = opts["integer"].value
        if isinstance(v, ast.Bool):
            integer = v.value
        else:
            ctx.sink.error("E0204", "`integer` is true or false", v.span)
            return None
    if dist == "poisson":
        integer = True  # counts
    if integer:
        bad = [x for x in [default, *choices, *(b for b in (lo, hi) if b is not None)]
               if abs(x - round(x)) > INT_EPS]
        if bad:
            ctx.sink.error("E0204", f"integer parameter '{d.name}' has a fractional value {bad[0]!r}",
                           d.span)
            return None
    return P.ParamPlan(name=d.name, dimension=units.dim_name(dim), default=default,
                       low=lo, high=hi, distribution=dist, mean=mean, sd=sd,
                       choices=choices, bins=bins, weights=weights, integer=integer)


def _weights(ctx: Context, st: ast.Setting, name: str) -> list[float] | None:
    if not isinstance(st.value, ast.ListExpr):
        ctx.sink.error("E0204", f"the weights of '{name}' are a list: `weights [1, 2, 1]`", st.value.span)
        return None
    vals = lower_list(ctx, st.value, units.DIMENSIONLESS, f"the weights of '{name}'")
    if vals is None:
        return None
    if any(w < 0.0 for w in vals) or not sum(vals) > 0.0 or _absurd(ctx, vals, f"the weights of '{name}'",
                                                                     st.value.span, units.DIMENSIONLESS):
        ctx.sink.error("E0301", f"the weights of '{name}' must be non-negative with a positive sum", st.value.span)
        return None
    return vals


def _bins(ctx: Context, st: ast.Setting, name: str, dim, lo: float, hi: float, n_weights: int) -> list[float] | None:
    if not isinstance(st.value, ast.ListExpr):
        ctx.sink.error("E0204", f"the bins of '{name}' are a list of edges: `bins [0, 2, 10] m`", st.value.span)
        return None
    edges = lower_list(ctx, st.value, dim, f"the bins of '{name}'")
    if edges is None or _absurd(ctx, edges, f"the bins of '{name}'", st.value.span, dim):
        return None
    if len(edges) != n_weights + 1:
        ctx.sink.error("E0204", f"{len(edges)} bin edges for {n_weights} weights of '{name}'", st.value.span,
                       "n bins have n + 1 edges and n weights")
        return None
    if any(b <= a for a, b in zip(edges, edges[1:])):
        ctx.sink.error("E0204", f"the bin edges of '{name}' must increase", st.value.span)
        return None
    if edges[0] < lo or edges[-1] > hi:
        ctx.sink.error("E0301", f"the bins of '{name}' reach outside its range {range_text(lo, hi, dim)}",
                       st.value.span)
        return None
    return edges


def _absurd(ctx: Context, values, what: str, span, dim) -> bool:
    """True (reported, E0301) when a value is beyond MAX_ABS_NUMBER: finite, but a
    sampler would overflow on it (a range of ±1e308 is an infinite width)."""
    bad = next((v for v in values if abs(v) > MAX_ABS_NUMBER), None)
    if bad is None:
        return False
    ctx.sink.error("E0301", f"{what} ({fmt(bad, dim)}) is beyond ±{MAX_ABS_NUMBER:g} (SI units)", span,
                   "no quantity of a driving scenario is this large (docs/limits.md)")
    return True
