"""Falsification vs uniform random sampling: runs needed to the first failure.

    PYTHONPATH=. python benchmarks/bench_search.py [--scenario examples/lead_brake.addt]
        [--seeds 8] [--budget 150] [--batch 8] [--jobs 2]

Both samplers search the same space (`addt_dsl.search.falsify.SearchSpace`: parameters,
fault presence, times and magnitudes) with the same budget; the cross-entropy sampler's
first batch has the same distribution as random sampling. A seed that finds no failure
within the budget counts as budget + 1 runs (censored; reported). Prints per-seed
figures, the mean and median runs to first failure, and the ratio random / CEM
(> 1: the guided search needs fewer runs).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import _figures as figures_json  # noqa: E402
from addt_dsl.compiler import compile_file  # noqa: E402
from addt_dsl.search.falsify import Falsifier  # noqa: E402


def first_failure(plan, sampler: str, seed: int, budget: int, batch: int, jobs: int) -> tuple[int, bool, float]:
    t0 = time.perf_counter()
    report = Falsifier(plan, seed=seed, batch=batch, jobs=jobs, sampler=sampler).run(
        budget_runs=budget, shrink_simulations=0, stop_at_first=True)
    found = report.first_failure_run is not None
    return (report.first_failure_run if found else budget + 1), found, time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default=str(ROOT / "examples" / "lead_brake.addt"))
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--budget", type=int, default=150)
    ap.add_argument("--batch", type=int, default=8)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--json", help="also write the figures here")
    args = ap.parse_args()
    plan = compile_file(args.scenario).plan
    results: dict[str, list[tuple[int, bool]]] = {"cem": [], "random": []}
    seconds = {"cem": 0.0, "random": 0.0}
    print(f"scenario {plan.name}: budget {args.budget} runs, batch {args.batch}, {args.seeds} seeds")
    print(f"{'seed':>4}  {'random':>8}  {'cem':>8}")
    for seed in range(args.seeds):
        row = []
        for sampler in ("random", "cem"):
            runs, found, secs = first_failure(plan, sampler, seed, args.budget, args.batch, args.jobs)
            results[sampler].append((runs, found))
            seconds[sampler] += secs
            row.append(f"{runs:>7}{'' if found else '+'}")
        print(f"{seed:>4}  {row[0]:>8}  {row[1]:>8}", flush=True)
    summary = {}
    for sampler, rows in results.items():
        runs = [r for r, _ in rows]
        summary[sampler] = (statistics.mean(runs), statistics.median(runs), sum(not f for _, f in rows))
        print(f"{sampler:>6}: mean {summary[sampler][0]:.1f} runs, median {summary[sampler][1]:.1f}, "
              f"censored {summary[sampler][2]}/{len(rows)}, {seconds[sampler]:.0f} s")
    print(f"ratio random/cem (mean runs to first failure): {summary['random'][0] / summary['cem'][0]:.2f}")
    print(f"ratio random/cem (median): {summary['random'][1] / summary['cem'][1]:.2f}")
    figures_json.write(args.json, {
        "scenario": plan.name, "budget_runs": args.budget, "seeds": args.seeds,
        **{sampler: {"mean_runs_to_failure": m, "median_runs_to_failure": med, "censored": c, "wall_s": seconds[sampler]}
           for sampler, (m, med, c) in summary.items()},
        "ratio_random_to_cem_mean": summary["random"][0] / summary["cem"][0],
        "ratio_random_to_cem_median": summary["random"][1] / summary["cem"][1]})


if __name__ == "__main__":
    main()
