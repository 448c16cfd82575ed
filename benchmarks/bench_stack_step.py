"""Where a `bev` stack step's time goes: per-call cost of its nodes, by perf_counter.

Run: PYTHONPATH=. python benchmarks/bench_stack_step.py [--agents 1,50] [--repeats 3] [--versus CHECKOUT]

One ground-truth run of `bench_dense`'s road (4 s) per agent count, with timers on the
stack's entry points (`BevStack.step`, `on_frame`, `_run_planner`, `_run_control`) and on the
nodes they call (`Controller.command`, `LatticePlanner.plan`, `Tracker.update`,
`GroundTruthPerception.run`): the median microseconds per call and the mean per run-step
(garbage collections included), each the least of `--repeats` runs; the timers add ~0.2 us
a call. `--versus CHECKOUT` times that checkout's
code (its `addt_dsl` first on the path) in the same invocation, runs alternating, and
prints the ratios (other / this). Each measurement is a fresh worker process.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import _figures as figures_json  # noqa: E402

ROOT = HERE.parent
# (module, class, attribute, label): the timed calls
TARGETS = (
    ("addt_dsl.stack.bev", "BevStack", "step", "step"),
    ("addt_dsl.stack.bev", "BevStack", "on_frame", "on_frame"),
    ("addt_dsl.stack.bev", "BevStack", "_run_planner", "run_planner"),
    ("addt_dsl.stack.bev", "BevStack", "_run_control", "run_control"),
    ("addt_dsl.stack.nodes", "Controller", "command", "control.command"),
    ("addt_dsl.stack.nodes", "LatticePlanner", "plan", "planner.plan"),
    ("addt_dsl.stack.nodes", "Tracker", "update", "tracker.update"),
    ("addt_dsl.stack.nodes", "GroundTruthPerception", "run", "perception.run"),
)


def worker(n_agents: int, duration: float) -> dict:
    """One timed run in this process: {label: (calls, total s)}, steps, digest."""
    import importlib

    sys.path.insert(0, str(HERE))
    from bench_dense import dense_source, spec_of

    from addt_dsl.runtime.execute import execute

    spec = spec_of(dense_source(n_agents, "ground_truth", duration))
    execute(spec, keep_trace=False)  # compile the kernels, warm the caches
    totals: dict[str, list] = {}
    for module, cls, attr, label in TARGETS:
        owner = getattr(importlib.import_module(module), cls)
        original = getattr(owner, attr)
        acc = totals.setdefault(label, [])

        def wrapper(*args, _original=original, _acc=acc, **kwargs):
            t0 = time.perf_counter()
            try:
                return _original(*args, **kwargs)
            finally:
                _acc.append(time.perf_counter() - t0)

        setattr(owner, attr, wrapper)
    r = execute(spec, keep_trace=False)
    return {"totals": {k: (len(v), statistics.median(v) if v else 0.0, sum(v)) for k, v in totals.items()},
            "steps": len(totals["step"]), "digest": r.digest}


def measure(checkout: Path, n_agents: int, duration: float) -> dict:
    env = {**os.environ, "PYTHONPATH": str(checkout)}
    out = subprocess.run([sys.executable, __file__, "--worker", str(n_agents), str(duration)], env=env,
                         capture_output=True, text=True, check=True, cwd=checkout)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--agents", default="1,50")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--duration", type=float, default=4.0)
    ap.add_argument("--versus", help="another checkout to time in the same invocation")
    ap.add_argument("--worker", nargs=2, help=argparse.SUPPRESS)
    ap.add_argument("--json", help="also write the figures here")
    a = ap.parse_args()
    if a.worker:
        print(json.dumps(worker(int(a.worker[0]), float(a.worker[1]))))
        return
    checkouts = {"this": ROOT}
    if a.versus:
        checkouts["versus"] = Path(a.versus).resolve()
    load = os.getloadavg()
    print(f"bev stack step, ground truth, {a.duration:g} s runs; least of {a.repeats}; "
          f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} on {os.cpu_count()} cores")
    figures: dict = {"load_average": load, "duration_s": a.duration, "per_call_us": {}}
    for n in (int(x) for x in a.agents.split(",")):
        best: dict[str, dict[str, float]] = {k: {} for k in checkouts}
        calls: dict[str, dict[str, int]] = {k: {} for k in checkouts}
        digests = {}
        for _ in range(a.repeats):
            for name, path in checkouts.items():  # alternating: the load drifts alike
                r = measure(path, n, a.duration)
                digests[name] = r["digest"]
                for label, (count, median, total) in r["totals"].items():
                    per_call = median * 1e6
                    per_step = total / r["steps"] * 1e6
                    old = best[name].get(label)
                    best[name][label] = (per_call, per_step) if old is None else \
                        (min(old[0], per_call), min(old[1], per_step))
                    calls[name][label] = count
        same = "equal" if len(set(digests.values())) == 1 else "DIFFER"
        print(f"\n  {n} agents: median us per call (mean us per run-step)"
              + ("" if len(checkouts) == 1 else f"; digests {same}"))
        head = f"  {'':18s}{'calls':>7s}  {'this':>18s}"
        if "versus" in checkouts:
            head += f"  {'versus':>18s}  {'versus/this':>11s}"
        print(head)
        for _, _, _, label in TARGETS:
            this = best["this"].get(label, (0.0, 0.0))
            row = f"  {label:18s}{calls['this'].get(label, 0):7d}  {this[0]:8.2f} ({this[1]:6.2f})"
            if "versus" in checkouts:
                other = best["versus"].get(label, (0.0, 0.0))
                ratio = other[0] / this[0] if this[0] else float("nan")
                row += f"  {other[0]:8.2f} ({other[1]:6.2f})  {ratio:10.2f}x"
            print(row, flush=True)
        figures["per_call_us"][n] = {name: {label: {"median_per_call": v[0], "mean_per_step": v[1]}
                                            for label, v in best[name].items()} for name in checkouts}
    figures_json.write(a.json, figures)


if __name__ == "__main__":
    main()
