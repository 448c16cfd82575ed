"""Fault studies over a suite: outcome classes, success tables, perception errors.

    addtc study classify FILE [--jobs N] [--by P,Q]
        every run of FILE's sweep classified (masked / silent / detected / hazard) against
        its fault-free twin; counts and success rate per value of the grid parameters.
    addtc study table RUNS_CSV --by P,Q
        success rate per cell, with its 95 % Wilson interval, from an `addtc FILE --out DIR`
        run (DIR/runs.csv); from a classified run (`--classify`) over the runs whose
        fault-free twin passed, the others counted apart.
    addtc study perception FILE [--jobs N] [--by P] [--bands 0,20,40,60,80]
        mean position and heading error of detected objects by distance band, per value of
        the grid parameters (e.g. a sensor yaw shift).
    addtc study impact FILE [--jobs N] [--by P,Q]
        per cell of the grid: runs, runs without an ego collision (avoided), and the ego's
        speed and the speed relative to what it hit at the first impact [km/h] (Euro NCAP
        AEB tables, examples/suites/ncap_aeb_*.addt).

Perception errors come from the `detections` events the stack records (what perception
reported, world frame, with the frame's timestamp) compared with the ground truth in the
trace at that instant; detections are matched to actors by minimum total distance.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Sequence

import numpy as np

from addt_dsl import units
from addt_dsl.console import compile_and_report, stack_option
from addt_dsl.errors import EXIT_USAGE, UsageError, nonneg_int, positive_int
from addt_dsl.runtime.executor import default_batch, local_executor, run_batch, run_spec
from addt_dsl.runtime.outcome import FAULT_OUTCOMES, classify_many, outcome_table, wilson_interval
from addt_dsl.sweep import expand

DEFAULT_BANDS_M = (0.0, 20.0, 40.0, 60.0, 80.0)


def perception_errors(trace, gate_m: float = 15.0) -> list[dict]:
    """One row per matched detection: time, actor, range from the ego [m], errors [m, rad]."""
    from scipy.optimize import linear_sum_assignment

    others = [n for n in trace.actors if n != "ego"]
    ego = trace.actors["ego"]
    rows = []
    n = len(trace.time)
    for e in trace.events:
        if e.kind != "detections" or not e.detail["objects"] or not others:
            continue
        k = int(round(e.detail["stamp_s"] / trace.period_s))
        if not 0 <= k < n:
            continue
        gt = np.array([[trace.actors[a].x[k], trace.actors[a].y[k]] for a in others])
        det = np.array([[o[0], o[1]] for o in e.detail["objects"]])
        cost = np.hypot(det[:, None, 0] - gt[None, :, 0], det[:, None, 1] - gt[None, :, 1])
        for i, j in zip(*linear_sum_assignment(cost)):
            if cost[i, j] > gate_m:
                continue  # a ghost or a miss, not a misplaced detection
            actor = trace.actors[others[j]]
            rows.append({
                "time_s": float(trace.time[k]), "actor": others[j],
                "range_m": float(math.hypot(actor.x[k] - ego.x[k], actor.y[k] - ego.y[k])),
                "position_error_m": float(cost[i, j]),
                "heading_error_rad": abs(units.wrap_angle(float(e.detail["objects"][i][2]) - float(actor.heading[k]))),
            })
    return rows


def error_table(rows: Sequence[dict], by: Sequence[str] = (), bands: Sequence[float] = DEFAULT_BANDS_M):
    """Mean position error [m] and heading error [deg] per distance band (and `by` columns)."""
    import pandas as pd

    df = pd.DataFrame(rows)
    if df.empty:
        return df
    labels = [f"{int(a)}-{int(b)} m" for a, b in zip(bands[:-1], bands[1:])]
    df["band"] = pd.cut(df["range_m"], list(bands), labels=labels, right=False)
    df["heading_error_deg"] = np.degrees(df["heading_error_rad"])
    grouped = df.groupby([*by, "band"], observed=True)
    return grouped.agg(position_error_m=("position_error_m", "mean"),
                       heading_error_deg=("heading_error_deg", "mean"),
                       detections=("position_error_m", "size"))


def success_table(runs, by: Sequence[str]):
    """Success rate per cell of an `addtc --out` runs table (columns `param.NAME`, `passed`),
    with its 95 % Wilson interval (`lo`, `hi`).

    A classified table (`addtc --classify`: an `outcome` column) is rated as fault campaigns
    are: only runs whose fault-free twin passed count (`n`; `passed` and the rate are over
    them), and the runs left out are counted apart (`twin_failed`, and `error` for runs the
    runner could not classify); `hazard` counts the fault-caused failures among the n."""
    cols = [f"param.{b}" for b in by]
    missing = [b for b, c in zip(by, cols) if c not in runs.columns]
    if missing or "passed" not in runs.columns:
        known = ", ".join(c.removeprefix("param.") for c in runs.columns if c.startswith("param.")) or "none"
        raise UsageError(f"--by {','.join(missing)}: not a parameter of these runs (parameters: {known})"
                         if missing else "not a runs table of `addtc FILE --out DIR` (no `passed` column)")
    runs = runs.copy()
    runs["passed"] = runs["passed"].astype(bool)
    classified = "outcome" in runs.columns and runs["outcome"].notna().any()
    if classified:
        outcome = runs["outcome"].fillna("")
        runs["sample"] = outcome.isin(FAULT_OUTCOMES)
        runs["twin_failed"] = outcome == "twin_failed"
        runs["error"] = ~runs["sample"] & ~runs["twin_failed"]
        runs["hazard"] = outcome == "hazard"
        runs["ok"] = runs["passed"] & runs["sample"]
        grouped = runs.groupby(cols)
        table = grouped.agg(runs=("passed", "size"), twin_failed=("twin_failed", "sum"), error=("error", "sum"),
                            n=("sample", "sum"), passed=("ok", "sum"), hazard=("hazard", "sum"))
        k, n = table["passed"], table["n"]
    else:
        table = runs.groupby(cols).agg(runs=("passed", "size"), passed=("passed", "sum"))
        k, n = table["passed"], table["runs"]
    table["success_rate"] = [a / b if b else math.nan for a, b in zip(k, n)]
    bounds = [wilson_interval(int(a), int(b)) for a, b in zip(k, n)]
    table["lo"] = [lo for lo, _ in bounds]
    table["hi"] = [hi for _, hi in bounds]
    table.index.names = list(by)
    return table


def impact(trace) -> dict:
    """The ego's first collision in a trace: whether there was one, the ego's speed and the
    closing speed along the ego's heading at that instant [km/h] (NaN without one)."""
    hits = [e for e in trace.events_of("collision") if "ego" in e.detail.get("actors", ())]
    if not hits:
        return {"collided": False, "other": "", "impact_kmh": math.nan, "relative_kmh": math.nan}
    first = hits[0]
    other = next(a for a in first.detail["actors"] if a != "ego")
    k = min(int(round(first.time_s / trace.period_s)), len(trace.actors["ego"].speed) - 1)
    ego, obj = trace.actors["ego"], trace.actors[other]
    along = obj.speed[k] * math.cos(obj.heading[k] - ego.heading[k])
    return {"collided": True, "other": other, "impact_kmh": units.from_si(float(ego.speed[k]), "km/h"),
            "relative_kmh": units.from_si(float(ego.speed[k] - along), "km/h")}


def impact_table(rows: Sequence[dict], by: Sequence[str]):
    """Per cell: runs, avoided (no ego collision), avoided share, mean impact and relative
    speed over the runs that collided [km/h]."""
    import pandas as pd

    frame = pd.DataFrame(rows)
    keys = list(by) if by else ["all"]
    if not by:
        frame["all"] = "all"
    grouped = frame.groupby(keys)
    table = pd.DataFrame({
        "runs": grouped.size(),
        "avoided": grouped["collided"].apply(lambda c: int((~c.astype(bool)).sum())),
        "impact_kmh": grouped["impact_kmh"].mean(),
        "relative_kmh": grouped["relative_kmh"].mean(),
    })
    table.insert(2, "avoided_rate", table["avoided"] / table["runs"])
    return table


# ---------------------------------------------------------------- running a suite

def _record_errors(result) -> None:
    result.stats["perception_errors"] = perception_errors(result.trace)


def perception_run(spec, seq: int = -1, worker: str = ""):
    """What an executor's worker runs for `study perception`: the run, with its matched
    detections in `stats["perception_errors"]`."""
    return run_spec(spec, seq, worker, on_result=_record_errors)


def perception_batch(specs, seqs, worker: str = ""):
    """`perception_run` over a batch stepped together (the executors hand it `--batch` runs)."""
    return run_batch(specs, seqs, worker, on_result=_record_errors)


perception_run.run_batch = perception_batch


def _record_impact(result) -> None:
    result.stats["impact"] = impact(result.trace)


def impact_run(spec, seq: int = -1, worker: str = ""):
    """What an executor's worker runs for `study impact`: the run, with its first ego
    collision in `stats["impact"]`."""
    return run_spec(spec, seq, worker, on_result=_record_impact)


def impact_batch(specs, seqs, worker: str = ""):
    """`impact_run` over a batch stepped together."""
    return run_batch(specs, seqs, worker, on_result=_record_impact)


impact_run.run_batch = impact_batch


def _bands(text: str) -> list[float]:
    """`--bands 0,20,40`: increasing distance band edges [m]."""
    try:
        edges = [float(b) for b in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected increasing distances in m, like 0,20,40; got {text!r}") from None
    if len(edges) < 2 or any(b <= a for a, b in zip(edges, edges[1:])):
        raise argparse.ArgumentTypeError(f"expected at least two increasing distances, got {text!r}")
    return edges


def main(argv: list[str] | None = None, prog: str = "addtc study") -> int:
    import pandas as pd

    parser = argparse.ArgumentParser(prog=prog)
    sub = parser.add_subparsers(dest="what", required=True)
    for name in ("classify", "perception", "impact"):
        p = sub.add_parser(name)
        p.add_argument("file")
        p.add_argument("--jobs", type=positive_int, default=1)
        p.add_argument("--batch", type=positive_int, default=None, metavar="N",
                       help="runs each worker steps together (default: the executors' default for the runs "
                            "and --jobs; the same tables at any N)")
        p.add_argument("--by", default="", help="grid parameters to group by (default: all grid axes)")
        p.add_argument("--limit", type=nonneg_int, default=0)
        stack_option(p)
        if name == "perception":
            p.add_argument("--bands", type=_bands, default=DEFAULT_BANDS_M)
    t = sub.add_parser("table")
    t.add_argument("runs_csv")
    t.add_argument("--by", required=True)
    args = parser.parse_args(argv)
    pd.set_option("display.width", 200)

    if args.what == "table":
        try:
            runs = pd.read_csv(args.runs_csv)
        except (pd.errors.EmptyDataError, pd.errors.ParserError, UnicodeDecodeError) as exc:
            raise UsageError(f"{args.runs_csv}: not a runs table ({str(exc).splitlines()[0]})") from None
        print(success_table(runs, args.by.split(",")).to_string(float_format=lambda x: f"{x:.3f}"))
        return 0

    result = compile_and_report(args.file, stack=args.stack)
    if not result.ok:
        return EXIT_USAGE
    plan = result.plan
    specs = expand(plan).specs
    if args.limit:
        specs = specs[: args.limit]
    by = args.by.split(",") if args.by else [g.param for g in plan.sweep.grid]
    unknown = [b for b in by if b not in {p.name for p in plan.params}]
    if unknown:
        raise UsageError(f"--by {','.join(unknown)}: not a parameter of {plan.name} "
                         f"(parameters: {', '.join(p.name for p in plan.params) or 'none'})")
    batch = args.batch or default_batch(len(specs), args.jobs)
    if args.what == "classify":
        executor = local_executor(args.jobs, batch=batch)
        print(outcome_table(classify_many(specs, jobs=args.jobs, executor=executor), by=by).to_string())
    elif args.what == "impact":
        rows = []
        for record in local_executor(args.jobs, impact_run, batch=batch).imap(enumerate(specs)):
            if record.status in ("crashed", "timeout", "memory"):
                print(f"error: run {record.run_id} {record.status}: {record.error.splitlines()[0]}", file=sys.stderr)
                return EXIT_USAGE
            rows.append({**record.params, **record.stats["impact"]})
        # Speeds read better in km/h (the plan holds SI m/s).
        speeds = {p.name for p in plan.params if p.dimension == "speed" and p.name in by}
        for row in rows:
            for name in speeds:
                row[f"{name} [km/h]"] = round(units.from_si(row[name], "km/h"), 6)
        by = [f"{b} [km/h]" if b in speeds else b for b in by]
        print(impact_table(rows, by).to_string(float_format=lambda x: f"{x:.2f}"))
    else:
        rows = []
        for record in local_executor(args.jobs, perception_run, batch=batch).imap(enumerate(specs)):
            if record.status in ("crashed", "timeout", "memory"):
                print(f"error: run {record.run_id} {record.status}: {record.error.splitlines()[0]}", file=sys.stderr)
                return EXIT_USAGE
            rows += [{**record.params, **row} for row in record.stats["perception_errors"]]
        # Angles read better in degrees (the plan holds SI radians).
        angles = {p.name for p in plan.params if p.dimension == "angle" and p.name in by}
        for row in rows:
            for name in angles:
                row[f"{name} [deg]"] = round(math.degrees(row[name]), 6)
        by = [f"{b} [deg]" if b in angles else b for b in by]
        print(error_table(rows, by=by, bands=args.bands).to_string(float_format=lambda x: f"{x:.3f}"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
