"""Report figures (matplotlib, Agg backend), returned as base64 PNG for embedding.

Every figure is built from run summaries in the store (robustness per oracle, latency
histograms, e2e latency by object count), never from traces, so a report over 10,000
runs costs no simulation.
"""

from __future__ import annotations

import base64
import io
import json
import math
from collections import defaultdict

import numpy as np

from addt_dsl.runtime.store import LATENCY_BIN_S, LATENCY_BINS

NODE_ORDER = ("perception", "tracker", "planner", "control", "e2e")


def _pyplot():
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def _png_bytes(fig) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, bbox_inches="tight")
    _pyplot().close(fig)
    return buf.getvalue()


def _png(fig) -> str:
    return base64.b64encode(_png_bytes(fig)).decode("ascii")


def robustness_histograms(records_by_oracle: dict[str, list[float]]) -> dict[str, str]:
    """One histogram per oracle; ±inf (vacuous) values are counted in the title."""
    plt = _pyplot()
    out = {}
    for name, values in records_by_oracle.items():
        finite = [v for v in values if math.isfinite(v)]
        infinite = len(values) - len(finite)
        fig, ax = plt.subplots(figsize=(4.2, 2.6))
        if finite:
            ax.hist(finite, bins=min(40, max(5, len(finite) // 3)), color="#4c72b0")
        ax.axvline(0.0, color="#c44e52", linewidth=1.2, label="0: violated below")
        ax.set_xlabel("robustness")
        ax.set_ylabel("runs")
        ax.set_title(name + (f" ({infinite} run(s) ±inf)" if infinite else ""), fontsize=9)
        ax.legend(fontsize=7, loc="upper right")
        out[name] = _png(fig)
    return out


class LatencyStats:
    """Running sum of per-run latency histograms and e2e-by-object-count summaries
    (bounded size, whatever the number of runs)."""

    def __init__(self):
        self.hist: dict[str, list[int]] = {}
        self.by_objects: dict[int, list[float]] = defaultdict(lambda: [0, 0.0, 0.0])
        self.worst: dict[str, float] = {}

    def add(self, stats: dict) -> None:
        for node, bins in stats.get("latency_hist", {}).items():
            h = self.hist.setdefault(node, [0] * LATENCY_BINS)
            for i, c in bins.items():
                h[int(i)] += c
        for node, m in stats.get("latency_max_s", {}).items():
            self.worst[node] = max(self.worst.get(node, 0.0), m)
        for n, (count, total, mx) in stats.get("e2e_by_objects", {}).items():
            acc = self.by_objects[int(n)]
            acc[0] += count
            acc[1] += total
            acc[2] = max(acc[2], mx)

    def summary(self, budget_s: float | None = 0.1) -> dict:
        """Per node: percentiles [ms] (to the histogram's 2 ms bins, upper edges, at most the worst), worst
        and the share of time at or above the budget (when there is one); e2e mean/worst
        by object count."""
        nodes = {}
        for node in [n for n in NODE_ORDER if n in self.hist] + sorted(set(self.hist) - set(NODE_ORDER)):
            counts = self.hist[node]
            total = sum(counts)
            if not total:
                continue
            cumulative, edges = 0, {}
            for i, c in enumerate(counts):
                cumulative += c
                for q in (50, 95, 99):
                    if q not in edges and cumulative >= q / 100 * total:
                        edges[q] = (i + 1) * LATENCY_BIN_S * 1e3
            worst_ms = self.worst.get(node, float("nan")) * 1e3
            # A bin's upper edge can lie above every sample in it: no percentile above the worst.
            if math.isfinite(worst_ms):
                edges = {q: min(v, worst_ms) for q, v in edges.items()}
            nodes[node] = {"p50_ms": edges[50], "p95_ms": edges[95], "p99_ms": edges[99],
                           "max_ms": worst_ms, "ticks": total}
            if budget_s is not None:
                over = sum(c for i, c in enumerate(counts) if i * LATENCY_BIN_S >= budget_s - 1e-12)
                nodes[node]["share_at_or_over_budget"] = over / total
        by_objects = {str(n): {"mean_ms": acc[1] / acc[0] * 1e3, "max_ms": acc[2] * 1e3, "ticks": acc[0]}
                      for n, acc in sorted(self.by_objects.items()) if acc[0]}
        return {"budget_ms": None if budget_s is None else budget_s * 1e3, "bin_ms": LATENCY_BIN_S * 1e3,
                "nodes": nodes, "e2e_by_objects": by_objects}


def latency_distributions(hist: dict[str, list[int]], budget_s: float | None = 0.1) -> str | None:
    """Per-node latency distributions (share of time at each latency) with the budget line
    (none when the scenario declares no budget)."""
    nodes = [n for n in NODE_ORDER if n in hist] + sorted(set(hist) - set(NODE_ORDER))
    if not nodes:
        return None
    plt = _pyplot()
    fig, axes = plt.subplots(len(nodes), 1, figsize=(6.5, 1.35 * len(nodes) + 0.6), sharex=True)
    axes = [axes] if len(nodes) == 1 else list(axes)
    edges_ms = [i * LATENCY_BIN_S * 1e3 for i in range(LATENCY_BINS + 1)]
    top = max((i for n in nodes for i, c in enumerate(hist[n]) if c), default=0)
    xmax = max((budget_s or 0.0) * 1e3 * 1.3, (top + 2) * LATENCY_BIN_S * 1e3)
    for ax, node in zip(axes, nodes):
        counts = hist[node]
        total = sum(counts) or 1
        ax.stairs([c / total for c in counts], edges_ms, fill=True, color="#55a868", alpha=0.8)
        ax.set_ylabel(node, rotation=0, ha="right", va="center", fontsize=8)
        ax.set_yticks([])
        if budget_s is not None:
            over = sum(c for i, c in enumerate(counts) if i * LATENCY_BIN_S >= budget_s) / total
            ax.axvline(budget_s * 1e3, color="#c44e52", linewidth=1.2)
            ax.text(0.99, 0.8, f"{100 * over:.1f} % of time ≥ {_ms(budget_s)} ms", transform=ax.transAxes,
                    ha="right", fontsize=7, color="#c44e52" if over else "#555555")
    axes[-1].set_xlim(0, xmax)
    axes[-1].set_xlabel("latency [ms]" + ("  (red line: budget)" if budget_s is not None else ""))
    fig.suptitle("Latency per node (share of simulated time)", fontsize=9)
    return _png(fig)


def _ms(seconds: float) -> str:
    return f"{seconds * 1e3:.4g}"


def latency_vs_objects(by_objects: dict[int, list[float]], budget_s: float | None = 0.1) -> str | None:
    """Mean and worst e2e latency against the number of objects perception saw."""
    if not by_objects:
        return None
    plt = _pyplot()
    ns = sorted(by_objects)
    mean = [by_objects[n][1] / by_objects[n][0] * 1e3 for n in ns]
    worst = [by_objects[n][2] * 1e3 for n in ns]
    fig, ax = plt.subplots(figsize=(5.0, 2.8))
    ax.plot(ns, mean, "o-", color="#4c72b0", label="mean")
    ax.plot(ns, worst, "s--", color="#8172b2", label="worst")
    if budget_s is not None:
        ax.axhline(budget_s * 1e3, color="#c44e52", linewidth=1.2, label=f"{_ms(budget_s)} ms budget")
    ax.set_xlabel("objects seen by perception")
    ax.set_ylabel("e2e latency [ms]")
    ax.legend(fontsize=7)
    ax.set_title("End-to-end latency against object count", fontsize=9)
    return _png(fig)


def success_rate_chart(labels: list[str], rates: list[float], intervals: list[tuple[float, float]],
                       axis: str) -> str | None:
    if not labels:
        return None
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(max(3.5, 0.7 * len(labels) + 1.5), 2.6))
    xs = range(len(labels))
    pct = [100 * r for r in rates]
    err = [[max(0.0, 100 * (r - lo)) for r, (lo, _) in zip(rates, intervals)],
           [max(0.0, 100 * (hi - r)) for r, (_, hi) in zip(rates, intervals)]]
    ax.bar(xs, pct, color="#4c72b0", yerr=err, capsize=3)
    ax.set_xticks(list(xs), labels, rotation=30 if len(labels) > 6 else 0, fontsize=7)
    ax.set_ylim(0, 105)
    ax.set_ylabel("success [%]")
    ax.set_xlabel(axis)
    ax.set_title("Success rate per cell (95 % Wilson interval)", fontsize=9)
    return _png(fig)


TTC_PLOT_MAX_S = 15.0  # TTC is capped at 99 s ("not closing"); the interesting part is low


def fault_injections(events) -> dict[str, list[float]]:
    """Fault -> the times [s] it acted (the trace's `fault` events; an events table of
    `trace_view.events_table`), labelled `#index kind target`, in the scenario's order."""
    if events is None or not len(events):
        return {}
    out: dict[tuple[int, str], list[float]] = {}
    for row in events[events["kind"] == "fault"].itertuples():
        detail = json.loads(row.detail)
        key = (int(detail.get("index", 0)), f"#{detail.get('index', '?')} {detail.get('kind', '?')} "
                                            f"{detail.get('target', '')}".rstrip())
        out.setdefault(key, []).append(float(row.time_s))
    return {label: times for (_, label), times in sorted(out.items())}


LIGHT_COLOURS = {0.0: "#55a868", 1.0: "#dd8452", 2.0: "#c44e52"}  # plan.LIGHT_STATES: green, yellow, red


def signals_figure(table, verdicts, events=None, title: str = ""):
    """One run over time (a `trace_view.signals_table`): speeds, gaps and TTC from the ego,
    the ego's lane offset, each light's state, when each fault acted (one row per fault of
    the scenario, a tick at each injection; `events`: `trace_view.events_table`), and one
    panel per oracle with its margin (negative: violated), the zero line and the time its
    violation became certain (red; amber for a `warn` oracle). A matplotlib figure."""
    plt = _pyplot()
    t = table["time_s"].to_numpy()
    groups = [("speed [m/s]", [c for c in table.columns if c.endswith(".speed")]),
              ("gap from ego [m]", [c for c in table.columns if c.startswith("gap(")]),
              ("TTC from ego [s]", [c for c in table.columns if c.startswith("ttc(")]),
              ("ego lane offset [m]", [c for c in ("ego.lane_offset",) if c in table.columns])]
    groups = [(label, cols) for label, cols in groups if cols]
    lights = [c for c in table.columns if c.startswith("light(")]
    faults = fault_injections(events)
    rho = [v for v in verdicts if f"rho.{v.name}" in table.columns]
    extra = bool(lights) + bool(faults)
    n = len(groups) + extra + len(rho)
    fig, axes = plt.subplots(n, 1, figsize=(7.0, 1.25 * n + 0.6), sharex=True, squeeze=False)
    axes = list(axes[:, 0])
    panel = iter(axes[len(groups):len(groups) + extra])
    if lights:
        ax = next(panel)
        for row, c in enumerate(lights):
            states = table[c].to_numpy(dtype=float)
            for code, colour in LIGHT_COLOURS.items():  # a coloured band where the light shows that state
                ax.fill_between(t, row - 0.4, row + 0.4, where=states == code, color=colour, step="post",
                                linewidth=0)
        ax.set_yticks(range(len(lights)), [c[len("light("):-1] for c in lights], fontsize=6)
        ax.set_ylim(-0.6, len(lights) - 0.4)
        ax.set_ylabel("lights", fontsize=7)
    if faults:
        ax = next(panel)
        ax.eventplot(list(faults.values()), lineoffsets=list(range(len(faults))), linelengths=0.7,
                     colors="#8172b2", linewidths=1.0)
        ax.set_yticks(range(len(faults)), list(faults), fontsize=6)
        ax.set_ylim(-0.6, len(faults) - 0.4)
        ax.set_ylabel("faults\ninjected", fontsize=7)
        for times in faults.values():  # the first injection of each fault across the other panels
            for other in axes[:len(groups)]:
                other.axvline(times[0], color="#8172b2", linewidth=0.6, linestyle=":")
    for ax, (label, cols) in zip(axes, groups):
        for c in cols:
            ax.plot(t, table[c].to_numpy(), linewidth=1.0, label=c.replace(".speed", ""))
        if label.startswith("TTC"):
            ax.set_ylim(0, TTC_PLOT_MAX_S)
        ax.set_ylabel(label, fontsize=7)
        if len(cols) > 1 or label.startswith(("gap", "TTC")):
            ax.legend(fontsize=6, loc="upper right")
    for ax, v in zip(axes[len(groups) + extra:], rho):
        y = table[f"rho.{v.name}"].to_numpy(dtype=float)
        colour = "#55a868" if v.passed else ("#dd8452" if v.severity == "warn" else "#c44e52")
        finite = np.where(np.isfinite(y), y, np.nan)
        ax.plot(t, finite, color=colour, linewidth=1.0)
        ax.axhline(0.0, color="#555555", linewidth=0.7)
        if not v.passed:
            ax.fill_between(t, finite, 0.0, where=finite < 0, color=colour, alpha=0.25)
        if v.first_violation_s is not None:
            ax.axvline(v.first_violation_s, color=colour, linewidth=1.4, linestyle="--")
        state = "holds" if v.passed else ("warning" if v.severity == "warn" else "violated") + (
            f" at {v.first_violation_s:.2f} s" if v.first_violation_s is not None else "")
        ax.set_ylabel(f"{v.name}\nmargin", fontsize=7)
        ax.set_title(f"{v.name}: {state}", fontsize=7, loc="left", pad=2)
    for ax in axes:
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time [s]")
    if title:
        fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    return fig


def run_signals_png(table, verdicts, title: str = "", events=None) -> bytes:
    """`signals_figure` as PNG bytes."""
    return _png_bytes(signals_figure(table, verdicts, events, title))
