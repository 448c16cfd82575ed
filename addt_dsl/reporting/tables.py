"""Tables over run records: the runs table (pandas), the summary, success rates per
parameter cell, and the terminal verdict table.

Functions take any iterable of `RunRecord`s (a list, or `ResultStore.records()` to stream
a large sweep) so they serve both the store and in-memory results.
"""

from __future__ import annotations

import json
import math
from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass, field

from addt_dsl import units
from addt_dsl.errors import is_error_status
from addt_dsl.plan import ScenarioPlan
from addt_dsl.stats import wilson_interval


def run_row(r) -> dict:
    """One run's row of the runs table."""
    verdict = "pass" if r.passed else "error" if is_error_status(r.status) else "fail"
    row = {"run_id": r.run_id, "key": r.key, "seed": r.seed, "repeat": r.repeat_index,
           "passed": r.passed, "verdict": verdict, "status": r.status}
    row.update({f"param.{k}": v for k, v in sorted(r.params.items())})
    for v in r.verdicts:
        row[f"rho.{v.name}"] = v.robustness
    for v in r.verdicts:
        row[f"first_violation_s.{v.name}"] = v.first_violation_s
    row["failed_oracles"] = ";".join(r.failed_oracles)
    row["warned_oracles"] = ";".join(r.warned_oracles)
    row["sim_time_s"] = r.sim_time_s
    row["wall_time_s"] = r.wall_time_s
    row["fault_events"] = r.fault_events
    row["digest"] = r.digest
    row["error"] = r.error.splitlines()[0] if r.error else ""
    row["outcome"] = r.outcome
    return row


def runs_table(plan: ScenarioPlan, records: Iterable):
    """One row per run: id, parameters, seed, verdict, per-oracle robustness and first
    violation time, simulated and wall seconds (the whole table in memory: a large sweep's
    files are written by `runs_table_chunks`)."""
    import pandas as pd

    df = pd.DataFrame([run_row(r) for r in records])
    if "outcome" in df and not df["outcome"].astype(bool).any():
        df = df.drop(columns="outcome")  # not classified (`addtc --classify` fills it)
    return df


class _Column:
    """What one pass over the rows learns of a column: enough to give every chunk the dtype
    pandas would give the whole column."""

    __slots__ = ("missing", "kinds")

    def __init__(self, missing: bool):
        self.missing = missing
        self.kinds: set[type] = set()


def runs_layout(records: Iterable) -> tuple[list[str], dict[str, str]]:
    """The runs table's columns (in pandas' first-seen order, `outcome` dropped when no run was
    classified) and the dtypes the whole table would have where a chunk could infer another:
    int64 columns that are float64 over all rows (a float or a missing value elsewhere), and
    bool columns that are object over all rows (a missing value elsewhere)."""
    columns: dict[str, _Column] = {}
    rows = 0
    classified = False
    for r in records:
        row = run_row(r)
        classified |= bool(row["outcome"])
        for name, value in row.items():
            col = columns.get(name)
            if col is None:
                col = columns[name] = _Column(missing=rows > 0)
            col.kinds.add(type(value))
        if len(row) < len(columns):
            for name, col in columns.items():
                if name not in row:
                    col.missing = True
        rows += 1
    if not classified:
        columns.pop("outcome", None)
    dtypes = {}
    for name, col in columns.items():
        kinds = col.kinds - {type(None)}
        missing = col.missing or type(None) in col.kinds
        if kinds and kinds <= {int, float} and (float in kinds or missing):
            dtypes[name] = "float64"
        elif kinds == {bool} and missing:
            dtypes[name] = "object"
    return list(columns), dtypes


def runs_table_chunks(records: Iterable, layout: tuple[list[str], dict[str, str]], chunk: int):
    """The runs table in pieces of `chunk` rows, each with the whole table's columns and
    dtypes (`runs_layout` of the same records): concatenated, they are `runs_table`."""
    import pandas as pd

    columns, dtypes = layout
    rows = []

    def frame():
        df = pd.DataFrame(rows, columns=columns)
        for name, dtype in dtypes.items():
            if df[name].dtype != dtype:
                df[name] = df[name].astype(dtype)
        return df

    for r in records:
        rows.append(run_row(r))
        if len(rows) == chunk:
            yield frame()
            rows = []
    if rows:
        yield frame()


def summary(plan: ScenarioPlan, records: Iterable, rejected: Counter | None = None,
            cells: Iterable | None = None) -> dict:
    """Counts over runs: passed, failed, errors (runs the tool did not finish), failures per
    oracle (a crashed, timed-out or out-of-memory run counts under its status), runs with a violated `warn` oracle
    (`warned`, whether they passed or not) and warnings per oracle. For classified runs (`addtc --classify`)
    also `outcomes` (runs per outcome class) and, for a sweep with grid axes,
    `outcomes_per_cell` over `cells` (the classified records; default `records`)."""
    failures: Counter = Counter()
    warnings: Counter = Counter()
    warned = 0
    statuses: Counter = Counter()
    outcomes: Counter = Counter()
    runs = passed = errors = 0
    sim = wall = 0.0
    classified = []  # for the per-cell table when `cells` is not given
    for r in records:
        runs += 1
        passed += r.passed
        errors += is_error_status(r.status)
        statuses[r.status] += 1
        outcome = getattr(r, "outcome", "")
        if outcome:
            outcomes[outcome] += 1
            if cells is None:
                classified.append(r)
        sim += r.sim_time_s
        wall += r.wall_time_s
        for name in r.failed_oracles:
            failures[name] += 1
        names = r.warned_oracles
        warned += bool(names)
        warnings.update(names)
    out = {
        "scenario": plan.name,
        "source": plan.source_file,
        "runs": runs,
        "passed": passed,
        # Failed: a hard oracle was violated or the stack failed (`detected`). Errors: the
        # tool did not finish the run (crashed, timeout, memory), counted apart.
        "failed": runs - passed - errors,
        "errors": errors,
        "failures_per_oracle": dict(sorted(failures.items())),
        "warned": warned,
        "warnings_per_oracle": dict(sorted(warnings.items())),
        "statuses": dict(sorted(statuses.items())),
        "rejected_by_assumption": dict(rejected or {}),
        "sim_time_s": sim,
        "wall_time_s": wall,
    }
    if outcomes:
        out["outcomes"] = {name: outcomes.get(name, 0) for name in OUTCOME_CLASSES}
        axes = [g.param for g in plan.sweep.grid]
        if axes:
            out["outcomes_per_cell"] = outcome_cells(classified if cells is None else cells, axes)
    return out


# Outcome classes of `addt_dsl.runtime.outcome` (OUTCOMES plus the runner's own `error`).
OUTCOME_CLASSES = ("masked", "silent", "detected", "hazard", "twin_failed", "error")


def outcome_cells(records: Iterable, axes: list[str]) -> list[dict]:
    """Per grid cell: the grid values, runs per outcome class, runs, success rate and mean
    injections per run (`addt_dsl.runtime.outcome.outcome_table` over classified records)."""
    from addt_dsl.runtime.outcome import outcome_table

    table = outcome_table(((r, r.outcome) for r in records if r.outcome), by=axes)
    if table.empty:
        return []
    def plain(v):  # numpy scalars to Python; NaN (no runs to rate) to None, valid in JSON
        v = v.item() if hasattr(v, "item") else v
        return None if isinstance(v, float) and math.isnan(v) else v

    return [{k: plain(v) for k, v in row.items()} for row in table.reset_index().to_dict("records")]


def fmt_number(x: float | None) -> str:
    if x is None:
        return "-"
    if isinstance(x, float) and math.isinf(x):
        return "inf" if x > 0 else "-inf"
    if isinstance(x, float) and math.isnan(x):
        return "nan"
    return f"{x:.3g}"


def fmt_param(plan: ScenarioPlan, name: str, value: float) -> str:
    """`12 m/s`: a parameter value in SI with its canonical unit."""
    p = next((p for p in plan.params if p.name == name), None)
    unit = units.CANONICAL_UNIT.get(units.DIMENSIONS_BY_NAME.get(p.dimension)) if p else None
    text = f"{value:.4g}"
    return f"{text} {unit}" if unit else text


@dataclass
class CellStats:
    cell: dict[str, float]
    runs: int = 0
    passed: int = 0
    failures: Counter = field(default_factory=Counter)

    @property
    def rate(self) -> float:
        return self.passed / self.runs if self.runs else math.nan

    @property
    def interval(self) -> tuple[float, float]:
        return wilson_interval(self.passed, self.runs)


def cell_stats(records: Iterable) -> list[CellStats]:
    """Success rate per sweep cell (one cell per grid point; a sweep without a grid is one
    cell), in the grid's order."""
    cells: dict[str, CellStats] = {}
    order: dict[str, int] = {}
    for r in records:
        k = json.dumps(sorted(r.cell.items()))
        st = cells.get(k)
        if st is None:
            st = cells[k] = CellStats(dict(r.cell))
            order[k] = r.seq if r.seq >= 0 else len(order)
        st.runs += 1
        st.passed += r.passed
        for name in r.failed_oracles:
            st.failures[name] += 1
    return [cells[k] for k in sorted(cells, key=lambda k: order[k])]


def success_pivot(plan: ScenarioPlan, stats: list[CellStats]) -> dict | None:
    """Table-1 layout for a 1- or 2-axis grid: rows × columns of success rates, or None
    for other sweeps (the flat per-cell table is shown instead)."""
    axes = [g.param for g in plan.sweep.grid]
    if not stats or not 1 <= len(axes) <= 2:
        return None
    col_axis = axes[-1]
    row_axis = axes[0] if len(axes) == 2 else None
    cols = next(g.values for g in plan.sweep.grid if g.param == col_axis)
    rows = next(g.values for g in plan.sweep.grid if g.param == row_axis) if row_axis else [None]
    by = {(st.cell.get(row_axis) if row_axis else None, st.cell.get(col_axis)): st for st in stats}
    return {
        "row_axis": row_axis,
        "col_axis": col_axis,
        "columns": [fmt_param(plan, col_axis, c) for c in cols],
        "rows": [{"label": fmt_param(plan, row_axis, rv) if row_axis else plan.name,
                  "cells": [by.get((rv, cv)) for cv in cols]} for rv in rows],
    }


# ---------------------------------------------------------------------------- terminal

def _value_dim(e, params: dict) -> units.Dim | None:
    """The dimension of a value expression where it is certain (None: a bare number, whose
    unit the plan no longer holds, or anything built from one by `*` or `/`)."""
    from addt_dsl import expr as E
    from addt_dsl.registry import SIGNALS

    match e:
        case E.Signal(name=name):
            cls = SIGNALS.get(name.split("(", 1)[0])
            return None if cls is None or cls.boolean else cls.dim
        case E.Param(name=name):
            return params.get(name)
        case E.Unary(op="neg", arg=a):
            return _value_dim(a, params)
        case E.Call(fn=fn, args=args) if fn in ("abs", "min", "max"):
            dims = {_value_dim(a, params) for a in args} - {None}
            return dims.pop() if len(dims) == 1 else None
        case E.Binary(op=op, left=l, right=r) if op in ("+", "-"):
            dims = {_value_dim(l, params), _value_dim(r, params)} - {None}
            return dims.pop() if len(dims) == 1 else None
        case E.Binary(op=op, left=l, right=r) if op in ("*", "/"):
            dl, dr = _value_dim(l, params), _value_dim(r, params)
            if dl is None or dr is None:
                return None
            return dl * dr if op == "*" else dl / dr
    return None


def robustness_unit(plan: ScenarioPlan, formula) -> str:
    """The unit of an oracle's robustness (`m`, `s`): that of its comparisons when they all
    share one; "" when they do not, or it is not certain (the table then shows none)."""
    from addt_dsl import expr as E

    params = {p.name: units.DIMENSIONS_BY_NAME.get(p.dimension) for p in plan.params}
    dims = set()
    for node in E.walk(formula):
        if isinstance(node, E.Binary) and node.op in E.COMPARE_OPS:
            found = {_value_dim(node.left, params), _value_dim(node.right, params)} - {None}
            dims.add(found.pop() if len(found) == 1 else None)
        elif isinstance(node, E.Signal) and _value_dim(node, params) is None:
            dims.add(None)  # a state used as a formula (`started(x)`): ±1, no unit
    if len(dims) != 1:
        return ""
    dim = dims.pop()
    return units.CANONICAL_UNIT.get(dim, "") if dim is not None else ""


VERDICT_LEGEND = ("oracle columns: robustness, the margin by which the run kept (> 0) or broke (< 0) the oracle at "
                  "its worst moment, in the unit in brackets; red: failed, yellow: a `warn` oracle violated "
                  "(never fails a run)")


def print_verdicts(plan: ScenarioPlan, records: list, totals: dict | None = None, fmt: str = "text") -> None:
    """Verdict table of `records` (at most 40 rows: failing runs first when more) and the
    totals line; `totals` is a `summary()` (defaults to one over `records`)."""
    totals = totals or summary(plan, records)
    if fmt == "json":
        print(json.dumps(totals, indent=2))
        return
    from rich.table import Table

    console = terminal()
    names = [o.name for o in plan.oracles]
    cell_params = sorted({k for r in records for k in r.cell})
    classified = any(getattr(r, "outcome", "") for r in records)
    table = Table(title=f"{plan.name}: {totals['runs']} run(s)")
    table.add_column("run")
    for p in cell_params:
        table.add_column(p)
    table.add_column("verdict")
    if classified:
        table.add_column("outcome")
    from rich.markup import escape

    for o in plan.oracles:
        unit = robustness_unit(plan, o.formula)
        table.add_column(escape(f"{o.name} [{unit}]") if unit else o.name, justify="right")
    for r in records:
        by_name = {v.name: v for v in r.verdicts}
        verdict = "[green]pass[/]" if r.passed else f"[red]{'FAIL' if r.status == 'ok' else r.status.upper()}[/]"
        verdict += " [yellow](warning)[/]" if r.warned_oracles else ""
        rho = []
        for n in names:
            v = by_name.get(n)
            rho.append("-" if v is None else fmt_number(v.robustness) if v.passed else
                       f"[{'yellow' if v.severity == 'warn' else 'red'}]{fmt_number(v.robustness)}[/]")
        outcome = [OUTCOME_STYLE.get(r.outcome, "{}").format(r.outcome or "-")] if classified else []
        table.add_row(r.run_id, *[fmt_param(plan, p, r.cell[p]) if p in r.cell else "" for p in cell_params],
                      verdict, *outcome, *rho)
    console.print(table)
    if names and records:
        console.print(escape(VERDICT_LEGEND), style="dim")
    if totals["runs"] > len(records):
        console.print(f"(showing {len(records)} of {totals['runs']} runs)")
    console.print(totals_line(totals))
    if totals.get("outcomes"):
        console.print("outcomes: " + ", ".join(f"{n} {name}" for name, n in totals["outcomes"].items()))
    for r in records:
        if r.status not in ("ok",):
            console.print(f"[red]{r.run_id}: {r.status}: {r.error.splitlines()[0] if r.error else ''}[/]")


def totals_line(totals: dict) -> str:
    """`5 passed, 2 failed, 1 with warnings; failures per oracle: a 2, b 1; warnings per oracle: c 1`"""
    line = f"{totals['passed']} passed, {totals['failed']} failed"
    if totals.get("errors"):
        kinds = ", ".join(f"{s} {n}" for s, n in totals["statuses"].items() if is_error_status(s))
        line += f", {totals['errors']} error(s) ({kinds}: the tool did not finish them)"
    if totals.get("warned"):
        line += f", {totals['warned']} with warnings"
    if totals["failed"] or totals.get("errors"):
        line += f"; failures per oracle: {_counts(totals['failures_per_oracle'])}"
    if totals.get("warned"):
        line += f"; warnings per oracle: {_counts(totals['warnings_per_oracle'])}"
    return line


def _counts(counts: dict) -> str:
    """`no_collision 2, reach_goal 1` (not a Python dict)."""
    return ", ".join(f"{k} {v}" for k, v in counts.items()) or "none"


def terminal():
    """A rich Console for tables: the terminal's width on a terminal; off a terminal (CI
    logs, files) wide enough that no column is cut ("no_coll..."), unless COLUMNS says
    otherwise."""
    import os
    import sys

    from rich.console import Console

    wide = not sys.stdout.isatty() and "COLUMNS" not in os.environ
    return Console(highlight=False, width=NON_TTY_WIDTH if wide else None)


NON_TTY_WIDTH = 400

OUTCOME_STYLE = {"masked": "[green]{}[/]", "silent": "[yellow]{}[/]", "detected": "[magenta]{}[/]",
                 "hazard": "[red]{}[/]", "twin_failed": "[dim]{}[/]", "error": "[red]{}[/]"}


def shown_records(store, limit: int = 40) -> list:
    """What the terminal table shows: every run of a small sweep, else failing runs first."""
    if len(store) <= limit:
        return list(store.records())
    failing = list(store.failing(limit=limit))
    return failing or list(store.records(limit=limit))


def latency_budget_s(plan: ScenarioPlan) -> float | None:
    """The latency budget the scenario declares: the bound of an oracle atom such as
    `latency(e2e) < 100 ms` (parameters at their nominal values), the e2e one if there is
    one, else the tightest on any node; None when no oracle bounds a latency."""
    from addt_dsl.expr import Binary, Num, Signal, substitute_params, walk

    bounds: dict[str, float] = {}
    nominal = plan.nominal_params()
    for o in plan.oracles:
        for node in walk(substitute_params(o.formula, nominal)):
            match node:
                case Binary(op="<" | "<=", left=Signal(name=name), right=Num(value=v)) | \
                        Binary(op=">" | ">=", left=Num(value=v), right=Signal(name=name)):
                    if name.startswith("latency("):
                        bounds[name] = min(v, bounds.get(name, math.inf))
    return bounds.get("latency(e2e)", min(bounds.values(), default=None))
