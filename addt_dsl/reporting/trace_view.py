"""One run's signals and events, for `addtc trace` and the report's per-run plots.

The store keeps no traces: `rerun` executes the stored RunSpec again with the trace kept
(a RunSpec determines its run; the stored digest says whether it did). `signals_table`
flattens the trace into one row per clock sample:

    time_s, ego.speed, ego.accel, ego.s, ego.lane_offset, ..., lead.speed, ...,
    gap(ego,lead), ttc(ego,lead), latency.e2e, ..., objects, light(<controller>), ...,
    step.<actor.step>, ..., rho.<oracle>, ...

where `rho.<oracle>` is the oracle's margin at each sample (`robustness_over_time`:
negative where it is violated). `events_table` lists the events (collisions, faults,
behaviours, detections, ...), one row each.
"""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np

from addt_dsl.errors import ToolError
from addt_dsl.expr import signals_used, substitute_params
from addt_dsl.fingerprint import code_identity, describe
from addt_dsl.runtime.oracles import robustness_over_time
from addt_dsl.runtime.signals import compute_signals
from addt_dsl.runtime.trace import ACTOR_FIELDS

# Events of these kinds come every sensor frame; the terminal lists them as a count only.
FREQUENT_EVENTS = ("detections",)


@dataclass
class RunTrace:
    """A stored run executed again: its spec, trace, verdicts and whether it reproduced."""

    record: object  # the stored RunRecord
    spec: object
    trace: object
    verdicts: list
    reproduced: bool
    other_code: str = ""  # the store's code, where it is not this code (`describe`)

    def mismatch(self) -> str:
        """Why the re-run is not the stored run, or "" where it is."""
        if self.reproduced:
            return ""
        if self.other_code:
            return (f"the re-run's trace digest differs from the stored one: the store was made by other "
                    f"code ({self.other_code}; this is {describe(code_identity())})")
        return "the re-run's trace digest differs from the stored one: not reproducible"


def stored_by_other_code(store) -> str:
    """The code that made `store`'s runs, described, where it is not this code; else ""."""
    stored = store.meta("code")
    identity = json.loads(stored) if stored else None
    return describe(identity) if identity != code_identity() else ""


class RerunFailed(ToolError):
    """A stored run, executed again, did not finish (its time or memory bound, a crash)."""


def run_keeping_trace(spec, seq: int = -1, worker: str = ""):
    """A worker's `run_fn` that keeps the trace (the sweep's `run_spec` drops it)."""
    from addt_dsl.runtime.execute import execute
    from addt_dsl.runtime.result import RunResult

    try:
        result = execute(spec, keep_trace=True)
    except Exception as exc:  # noqa: BLE001 - reported as the run's failure to finish
        return RunResult.unfinished(spec, "crashed", f"{type(exc).__name__}: {exc}", 0.0, seq=seq, worker=worker)
    result.seq, result.worker = seq, worker
    return result


def rerun(store, record) -> RunTrace:
    """Execute a stored run again, with its trace, in a worker process bounded as a sweep's
    (`LocalExecutor`: the run's time bound and the memory limit, docs/limits.md): a store
    names the run, and a run that hangs or grows without bound must not take this process
    with it. Raises `RerunFailed` when it does not finish."""
    from addt_dsl.runtime.executor import LocalExecutor

    spec = store.spec(record)
    executor = LocalExecutor(1, run_fn=run_keeping_trace, retries=0, max_tasks_per_child=1)
    (result,) = list(executor.imap([(0, spec)]))
    if result.status not in ("ok", "detected"):
        first = (result.error.splitlines() or [""])[0]
        raise RerunFailed(f"run {record.run_id}, executed again, did not finish ({result.status}: {first})")
    return RunTrace(record, spec, result.trace, result.verdicts,
                    reproduced=not record.digest or result.digest == record.digest,
                    other_code=stored_by_other_code(store))


def oracle_margins(spec, trace) -> dict[str, np.ndarray]:
    """Oracle name -> its margin at every sample (`robustness_over_time`)."""
    out = {}
    for o in spec.plan.oracles:
        formula = substitute_params(o.formula, spec.params)
        signals = compute_signals(trace, signals_used(formula))
        out[o.name] = np.asarray(robustness_over_time(formula, signals, trace.period_s), dtype=float)
    return out


def signals_table(spec, trace):
    """One row per clock sample: actor fields, gap and TTC from the ego to every other
    actor, per-node latency, object count and each oracle's margin (pandas)."""
    import pandas as pd

    columns: dict[str, np.ndarray] = {"time_s": np.asarray(trace.time)}
    for name, track in trace.actors.items():
        for f in ACTOR_FIELDS:
            columns[f"{name}.{f}"] = np.asarray(getattr(track, f))
    others = [n for n in trace.actors if n != "ego"]
    if "ego" in trace.actors:
        wanted = {f"{fn}(ego,{o})" for o in others for fn in ("gap", "ttc")}
        computed = compute_signals(trace, wanted)
        for o in others:
            columns[f"gap(ego,{o})"] = computed[f"gap(ego,{o})"]
            columns[f"ttc(ego,{o})"] = computed[f"ttc(ego,{o})"]
    for node, values in trace.latency.items():
        columns[f"latency.{node}"] = np.asarray(values)
    if trace.object_count is not None:
        columns["objects"] = np.asarray(trace.object_count)
    for name, state in trace.lights.items():  # `light(C)`: 0 green, 1 yellow, 2 red (plan.LIGHT_STATES)
        columns[f"light({name})"] = np.asarray(state, dtype=float)
    for name, state in trace.steps.items():  # named steps: 0 waiting, 1 started, 2 ended
        columns[f"step.{name}"] = np.asarray(state)
    for name, rho in oracle_margins(spec, trace).items():
        columns[f"rho.{name}"] = rho
    return pd.DataFrame(columns)


def events_table(trace):
    """One row per event: time, kind and its details as JSON (pandas)."""
    import pandas as pd

    rows = [{"time_s": e.time_s, "kind": e.kind, "detail": json.dumps(e.detail, default=_jsonable)}
            for e in trace.events]
    return pd.DataFrame(rows, columns=["time_s", "kind", "detail"])


def _jsonable(x):
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    return str(x)


def events_path(path) -> str:
    """Where `--csv runs/c000.csv` puts the events: `runs/c000-events.csv`."""
    from pathlib import Path

    p = Path(path)
    return str(p.with_name(f"{p.stem}-events{p.suffix}"))


def print_trace(run: RunTrace, table, events, max_events: int = 40) -> None:
    """Terminal view: the run and its verdicts, a summary per signal (min, max, mean, at
    the end) and the events in time order (frequent kinds counted)."""
    from rich.table import Table

    from addt_dsl.reporting.tables import fmt_number, terminal

    console = terminal()
    r = run.record
    params = ", ".join(f"{k} = {fmt_number(v)}" for k, v in sorted(r.params.items()))
    verdict = "pass" if r.passed else ("FAIL" if r.status == "ok" else r.status.upper())
    console.print(f"{run.spec.plan.name} {r.run_id}: {verdict} · seed {r.seed} · {params}")
    for v in run.verdicts:
        state = "holds" if v.passed else ("warning" if v.severity == "warn" else "VIOLATED")
        when = f", certain at {v.first_violation_s:.2f} s" if v.first_violation_s is not None else ""
        console.print(f"  {v.name}: {state}, robustness {fmt_number(v.robustness)}{when}")
    if not run.reproduced:
        console.print(f"[yellow]{run.mismatch()}[/]")
    summary = Table(title=f"signals ({len(table)} samples every {run.trace.period_s:g} s)")
    for col in ("signal", "min", "max", "mean", "at end"):
        summary.add_column(col, justify="left" if col == "signal" else "right")
    for col in table.columns[1:]:
        values = table[col].to_numpy(dtype=float)
        finite = values[np.isfinite(values)]
        cells = [fmt_number(float(x)) for x in (finite.min(), finite.max(), finite.mean())] if len(finite) \
            else ["-"] * 3
        summary.add_row(col, *cells, fmt_number(float(values[-1])) if len(values) else "-")
    console.print(summary)
    frequent = events[events["kind"].isin(FREQUENT_EVENTS)]["kind"].value_counts()
    listed = events[~events["kind"].isin(FREQUENT_EVENTS)]
    console.print(f"events: {len(events)}"
                  + "".join(f"; {n} {kind} (one per sensor frame, in the CSV)" for kind, n in frequent.items()))
    for row in listed.head(max_events).itertuples():
        console.print(f"  {row.time_s:7.2f} s  {row.kind:<12} {row.detail}", markup=False)
    if len(listed) > max_events:
        console.print(f"  ... {len(listed) - max_events} more (write them with --csv)")
    for line in unopened_windows(run.spec, run.trace):
        console.print(f"  {line}", markup=False)


def unopened_windows(spec, trace) -> list[str]:
    """The faults whose window a condition opens (`when C for W`) and that never opened: their
    condition did not fire before the run ended, so they never acted (no event says so)."""
    opened = {e.detail["index"] for e in trace.events if e.kind == "fault_window"}
    return [f"fault {f.index} ({f.kind} {f.target}): its window never opened, its condition did not "
            f"fire before the run ended; it never acted" for f in spec.faults
            if f.opens is not None and f.index not in opened]
