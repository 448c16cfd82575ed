"""The sweep: grid axes inside their parameters' ranges, one sampler, repeats, seed, rejection cap.
Run right after the parameters: a grid over a parameter without a range widens its range."""

from __future__ import annotations

import math
from dataclasses import dataclass

from addt_dsl import plan as P
from addt_dsl import units
from addt_dsl.compiler import ast
from addt_dsl.compiler.context import INT_EPS, Context, const_value, fmt, lower_list, source_unit, suggest
from addt_dsl.compiler.exprs import ExprLowering, Scope
from addt_dsl.diagnostics import Span


@dataclass(frozen=True)
class Sweep:
    sweep: P.SweepPlan
    # A parameter without a range spans its default and its grid's values: every later
    # check over parameter ranges (fault times, positions, windows) covers the whole sweep.
    param_ranges: dict[str, tuple[float, float]]


def rule_sweep(ctx: Context) -> Sweep:
    grid, cases, sampler, repeat, seed, max_rej = [], [], None, 1, 0, P.SweepPlan().max_rejections
    seen: dict[str, Span] = {}
    sampler_span: Span | None = None
    for block in ctx.blocks("sweep"):
        for item in block.items:
            key = item.name if item.kind == "grid" else ("sampler" if item.kind in ("random", "halton", "lhs")
                                                          else item.kind)
            if item.kind == "cases":
                key = None  # each column is checked against the other axes in _cases
            if key in seen:
                ctx.sink.error("E0102", f"{'grid of ' + key if item.kind == 'grid' else key} given twice",
                               item.span, f"first given at {seen[key]}")
                continue
            if key is not None:
                seen[key] = item.span
            if item.kind == "grid":
                vals = _axis_values(ctx, item.name, item.value, item.span, "grid")
                if vals is None:
                    continue
                grid.append(P.GridAxis(param=item.name, values=vals))
            elif item.kind == "cases":
                axis = _cases(ctx, item, seen)
                if axis is not None:
                    cases.append(axis)
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
        gridded = {g.param for g in grid} | {n for c in cases for n in c.params}
        sampled = [p for p in ctx.params if p.name not in gridded and
                   (p.choices or (p.low is not None and p.low < p.high))]
        if not sampled:
            ctx.sink.warning("W0002", f"`{sampler.kind}` has nothing to sample", sampler_span,
                             "give a parameter a range (`in [low, high]`) that no grid fixes")
    ranges = dict(ctx.param_ranges)
    columns = [(a.param, a.values) for a in grid]
    columns += [(name, [row[i] for row in c.rows]) for c in cases for i, name in enumerate(c.params)]
    for name, values in columns:
        lo, hi = ranges.get(name, (min(values), max(values)))
        ranges[name] = (min(lo, *values), max(hi, *values))
    return Sweep(P.SweepPlan(grid=grid, cases=cases, sampler=sampler, repeat=repeat, seed=seed,
                             max_rejections=max_rej), ranges)


def _axis_values(ctx: Context, name: str, node, span: Span, what: str) -> list[float] | None:
    """The values of a `grid` axis or a `cases` column: a list in the parameter's unit,
    inside its range, whole numbers for an integer parameter (None after a diagnostic)."""
    if name not in ctx.param_dims:
        ctx.sink.error("E0101", f"unknown parameter '{name}'", span, *suggest(name, ctx.param_dims))
        return None
    if not isinstance(node, ast.ListExpr):
        ctx.sink.error("E0204", f"a {what} takes a list: `{what} x in [1, 2, 3] m`", node.span)
        return None
    vals = lower_list(ctx, node, ctx.param_dims[name], f"the {what} of '{name}'")
    if vals is None:
        return None
    p = next((p for p in ctx.params if p.name == name), None)
    if p is not None and p.low is not None:
        outside = [v for v in vals if v < p.low - 1e-12 or v > p.high + 1e-12]
        if outside:
            dim = ctx.param_dims[name]
            unit = node.unit or source_unit(ctx.params_ast[name].default)
            ctx.sink.error("E0301", f"{what} value {fmt(outside[0], dim, unit)} is outside the range of "
                           f"'{name}' [{fmt(p.low, dim, unit)}, {fmt(p.high, dim, unit)}]",
                           node.span, f"a parameter's range is its domain: widen it to include the {what}")
            return None
    if p is not None and p.integer and any(abs(v - round(v)) > INT_EPS for v in vals):
        ctx.sink.error("E0204", f"'{name}' is an integer parameter; the {what} has fractions", node.span)
        return None
    return vals


def _cases(ctx: Context, item, seen: dict[str, Span]) -> P.CaseAxis | None:
    """`cases a in [1, 2] m, b in [3, 4] s`: columns of equal length, each parameter once
    in the sweep's axes."""
    columns: list[tuple[str, list[float]]] = []
    ok = True
    for col in item.settings:
        if col.key in seen:
            ctx.sink.error("E0102", f"'{col.key}' is already an axis of the sweep", col.key_span,
                           f"first given at {seen[col.key]}")
            ok = False
            continue
        seen[col.key] = col.key_span
        vals = _axis_values(ctx, col.key, col.value, col.key_span, "cases")
        if vals is None:
            ok = False
            continue
        columns.append((col.key, vals))
    if not ok:
        return None
    lengths = {len(v) for _, v in columns}
    if len(lengths) != 1:
        ctx.sink.error("E0204", "the columns of `cases` have different lengths ("
                       + ", ".join(f"{n}: {len(v)}" for n, v in columns) + ")", item.span,
                       "row i of `cases` is the i-th value of every column")
        return None
    return P.CaseAxis(params=[n for n, _ in columns], rows=[list(r) for r in zip(*[v for _, v in columns])])


def _int_of(ctx: Context, node, what: str, lo: int, hi: int) -> int | None:
    e = ExprLowering(ctx.sink, Scope({}, set(), set(), False, set())).lower_value(node, units.DIMENSIONLESS, what)
    if e is None:
        return None
    v = const_value(e)
    if v is None or not math.isfinite(v) or v != int(v) or not (lo <= v <= hi):
        ctx.sink.error("E0301", f"{what} must be a whole number in [{lo}, {hi}]", node.span)
        return None
    return int(v)
