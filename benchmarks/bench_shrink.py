"""Shrink cost for the 10-fault case: examples/ten_faults.addt injects ten faults of
which one (a stuck acceleration command) makes the run fail; the shrinker must reduce
the scenario to that one fault. Reports simulations, cache hits, rounds and seconds,
one candidate at a time and in batches (`--batch`, default 8: both in one invocation,
load average beside, each from a cold cache): the wall time to the minimal scenario and
the runs it took (judged, and run ahead for nothing). The shrunk scenario is the same at
any batch (checked here too); only the ratio within one invocation means anything on a
shared machine.

Run: python benchmarks/bench_shrink.py [--batch 8] [--jobs 1] [--json out.json]
Budget: at most 150 simulations.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import _figures as figures_json

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from addt_dsl.compiler import compile_file  # noqa: E402
from addt_dsl.search import RunCache, Shrinker  # noqa: E402
from addt_dsl.sweep import expand  # noqa: E402

BUDGET = 150


def _shrink(spec, plan, batch: int, jobs: int):
    cache = RunCache()
    try:
        cache.get(spec)  # the failing run itself, as `addtc shrink` has it from its search
        t0 = time.perf_counter()
        shrunk = Shrinker(spec, nominal_plan=plan, cache=cache, max_simulations=BUDGET, batch=batch,
                          jobs=jobs).run()
        return shrunk, time.perf_counter() - t0
    finally:
        cache.close()


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--batch", type=int, default=8, help="the batch compared with one at a time")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--json", help="also write the figures here")
    args = ap.parse_args()
    result = compile_file(ROOT / "examples" / "ten_faults.addt")
    (spec,) = expand(result.plan).specs
    figures = {"budget_simulations": BUDGET, "jobs": args.jobs, "load_before": figures_json.load()}
    rows = {}
    for batch in (1, args.batch):
        shrunk, wall = _shrink(spec, result.plan, batch, args.jobs)
        kept = [f"{f.kind} {f.target}" for f in shrunk.best.faults]
        runs = shrunk.simulations + shrunk.ran_ahead
        rows[batch] = (shrunk, wall)
        print(f"ten_faults batch {batch}: {len(spec.faults)} faults -> {len(kept)} ({', '.join(kept)}): "
              f"{wall:.1f} s wall, {runs} runs ({shrunk.simulations} judged + {shrunk.ran_ahead} run ahead), "
              f"{shrunk.cache_hits} cache hits, {shrunk.rounds} rounds; load {figures_json.load()}")
        if batch == 1:
            figures.update({"faults_before": len(spec.faults), "faults_after": kept,
                            "simulations": shrunk.simulations, "cache_hits": shrunk.cache_hits,
                            "rounds": shrunk.rounds, "seconds": wall, "ratio_to_budget": shrunk.simulations / BUDGET})
        else:
            figures.update({"batch": batch, "batch_seconds": wall, "batch_runs": runs,
                            "batch_ran_ahead": shrunk.ran_ahead})
    (one, t1), (many, tn) = rows[1], rows[args.batch]
    same = one.best.key() == many.best.key() and one.simulations == many.simulations
    figures.update({"batch_speedup": t1 / tn, "same_result": same})
    runs_ratio = (many.simulations + many.ran_ahead) / one.simulations
    print(f"batch {args.batch} vs 1: {t1 / tn:.2f}x wall time, {runs_ratio:.2f}x runs; "
          f"same shrunk scenario: {same}; load {figures_json.load()}")
    figures_json.write(args.json, figures)
    if not same:
        sys.exit("the batched shrink differs from the one at a time")


if __name__ == "__main__":
    main()
