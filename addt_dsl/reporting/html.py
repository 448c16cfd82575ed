"""The HTML report of a results store: one self-contained file (inline CSS, figures and
animations as base64 data URIs), rendered by jinja2 with autoescaping on.

Everything except the animations and signal plots comes from run summaries in the
store. Runs keep no trace, so for the failing runs chosen for animation the stored
RunSpec is executed again with the trace kept (`trace_view.rerun`); determinism makes
that the same run, and the report says whether the re-run's trace digest matched the
stored one. The latency budget drawn is the one the scenario's oracles declare.
"""

from __future__ import annotations

import base64
import datetime as _dt
import math
import time
from pathlib import Path

from addt_dsl.limits import DEFAULT_ANIMATION_BUDGET_S
from addt_dsl.reporting import plots
from addt_dsl.atomic import write_text
from addt_dsl.reporting.tables import (OUTCOME_CLASSES, cell_stats, fmt_number, fmt_param, latency_budget_s,
                                       success_pivot)
from addt_dsl.reporting.summary import store_summary

MAX_TABLE_ROWS = 500
# Animations re-run their run with the trace kept and draw every frame (5-15 s each): off
# unless asked for (`--animations N`), and then bounded in wall time as well.
DEFAULT_MAX_ANIMATIONS = 0


def _environment():
    from jinja2 import Environment, PackageLoader

    env = Environment(loader=PackageLoader("addt_dsl.reporting", "templates"), autoescape=True,
                      trim_blocks=True, lstrip_blocks=True)
    env.filters["num"] = fmt_number
    env.filters["pct"] = lambda x: "-" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{100 * x:.2f} %"
    return env


class _Collector:
    """One streaming pass over the store's records: bounded state whatever the run count."""

    def __init__(self, plan, max_rows: int, max_animations: int):
        self.plan = plan
        self.max_rows = max_rows
        self.max_animations = max_animations
        self.robustness: dict[str, list[float]] = {o.name: [] for o in plan.oracles}
        self.latency = plots.LatencyStats()
        self.rows: list = []
        self.failing_rows: list = []
        self.total = 0
        self.worst_per_oracle: dict[str, object] = {}
        self.worst_failing: list = []  # up to max_animations, lowest robustness first

    def add(self, r) -> None:
        self.total += 1
        for v in r.verdicts:
            self.robustness.setdefault(v.name, []).append(v.robustness)
        if r.stats:
            self.latency.add(r.stats)
        if len(self.rows) < self.max_rows:
            self.rows.append(r)
        if not r.passed and len(self.failing_rows) < self.max_rows:
            self.failing_rows.append(r)
        if not r.passed and r.status in ("ok", "detected"):
            for v in r.verdicts:
                if not v.passed and v.severity == "hard":
                    best = self.worst_per_oracle.get(v.name)
                    if best is None or v.robustness < _rho(best, v.name):
                        self.worst_per_oracle[v.name] = r
            self.worst_failing.append(r)
            self.worst_failing.sort(key=_worst_rho)
            del self.worst_failing[self.max_animations:]

    def animation_candidates(self) -> list:
        """The worst run of each failing oracle, then the worst failing runs overall."""
        chosen, seen = [], set()
        for o in self.plan.oracles:
            r = self.worst_per_oracle.get(o.name)
            if r is not None and r.run_id not in seen:
                chosen.append(r)
                seen.add(r.run_id)
        for r in self.worst_failing:
            if r.run_id not in seen:
                chosen.append(r)
                seen.add(r.run_id)
        return chosen[: self.max_animations]


def _rho(record, name: str) -> float:
    return next(v.robustness for v in record.verdicts if v.name == name)


def _worst_rho(record) -> float:
    values = [v.robustness for v in record.verdicts if not v.passed]
    return min(values) if values else math.inf


def _animate(store, record) -> dict:
    """A failing run executed again: its GIF and its signals over time."""
    from addt_dsl.reporting.animation import render_gif
    from addt_dsl.reporting.trace_view import events_table, rerun, signals_table

    run = rerun(store, record)
    gif = render_gif(run.spec.plan, run.trace, run.verdicts, label=record.run_id)
    signals = plots.run_signals_png(signals_table(run.spec, run.trace), run.verdicts,
                                    events=events_table(run.trace))
    return {
        "record": record,
        "gif": base64.b64encode(gif).decode("ascii"),
        "signals": base64.b64encode(signals).decode("ascii"),
        "reproduced": run.reproduced,
        "mismatch": run.mismatch(),
        "failing": [v for v in run.verdicts if not v.passed],
    }


def _animations(store, candidates: list, budget_s: float, clock=time.monotonic) -> tuple[list, list]:
    """Animate `candidates` in order until `budget_s` wall seconds are spent (the one in
    progress finishes); returns (animations, run ids left out for time, or past their bounds when
    executed again)."""
    from addt_dsl.reporting.trace_view import RerunFailed

    out, skipped = [], []
    start = clock()
    for r in candidates:
        if out and clock() - start >= budget_s:
            skipped.append(r.run_id)
            continue
        try:
            out.append(_animate(store, r))
        except RerunFailed:  # executed again past its time or memory bound: left out, as for time
            skipped.append(r.run_id)
    return out, skipped


def build_report(store, path: str | Path, max_animations: int = DEFAULT_MAX_ANIMATIONS,
                 budget_s: float | None = None, max_rows: int = MAX_TABLE_ROWS,
                 animation_budget_s: float = DEFAULT_ANIMATION_BUDGET_S) -> Path:
    """Write the HTML report of `store` to `path` (`budget_s` overrides the latency budget
    the plan's oracles declare). Up to `max_animations` failing runs are animated (none by
    default), within `animation_budget_s` wall seconds."""
    plan = store.plan()
    budget_s = budget_s if budget_s is not None else latency_budget_s(plan)
    collector = _Collector(plan, max_rows, max_animations)
    for r in store.records():
        collector.add(r)
    totals = store_summary(store)
    stats = cell_stats(store.records())
    pivot = success_pivot(plan, stats)
    latency = collector.latency
    axis_label = ", ".join(g.param for g in plan.sweep.grid) or "cell"
    cells = [{"label": ", ".join(f"{k} = {fmt_param(plan, k, v)}" for k, v in sorted(st.cell.items())) or "all runs",
              "short": ", ".join(fmt_param(plan, k, v) for k, v in sorted(st.cell.items())) or "all",
              "stats": st} for st in stats]
    figures = {
        "success": plots.success_rate_chart([c["short"] for c in cells], [c["stats"].rate for c in cells],
                                            [c["stats"].interval for c in cells], axis_label),
        "robustness": plots.robustness_histograms({k: v for k, v in collector.robustness.items() if v}),
        "latency": plots.latency_distributions(latency.hist, budget_s),
        "latency_objects": plots.latency_vs_objects(dict(latency.by_objects), budget_s),
    }
    table_rows = collector.rows if collector.total <= max_rows else collector.failing_rows
    animations, not_animated = _animations(store, collector.animation_candidates(), animation_budget_s)
    html = _environment().get_template("report.html.j2").render(
        plan=plan, totals=totals, store_path=str(store.path),
        generated=_dt.datetime.now().isoformat(timespec="seconds"),
        cells=cells, pivot=pivot, figures=figures, oracles=[o for o in plan.oracles],
        rows=table_rows, rows_truncated=collector.total > len(table_rows),
        budget_ms=None if budget_s is None else budget_s * 1e3, outcome_classes=OUTCOME_CLASSES,
        classified=bool(totals.get("outcomes")),
        worst_latency=latency.worst, animations=animations, not_animated=not_animated,
        animation_budget_s=animation_budget_s, max_animations=max_animations,
        cell_params=sorted({k for r in table_rows for k in r.cell}),
        fmt_param=fmt_param)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_text(path, html)
    return path
