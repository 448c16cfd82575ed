"""Shrink cost for the 10-fault case: examples/ten_faults.addt injects ten faults of
which one (a stuck acceleration command) makes the run fail; the shrinker must reduce
the scenario to that one fault. Reports simulations, cache hits, rounds and seconds.

Run: python benchmarks/bench_shrink.py [--json out.json]
Budget: at most 150 simulations.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import _figures as figures_json

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from addt_dsl.compiler import compile_file  # noqa: E402
from addt_dsl.search import RunCache, Shrinker  # noqa: E402
from addt_dsl.sweep import expand  # noqa: E402

BUDGET = 150


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--json", help="also write the figures here")
    args = ap.parse_args()
    result = compile_file(ROOT / "examples" / "ten_faults.addt")
    (spec,) = expand(result.plan).specs
    shrunk = Shrinker(spec, nominal_plan=result.plan, cache=RunCache(), max_simulations=BUDGET).run()
    kept = [f"{f.kind} {f.target}" for f in shrunk.best.faults]
    print(f"ten_faults: {len(spec.faults)} faults -> {len(kept)} ({', '.join(kept)}): "
          f"{shrunk.simulations} simulations, {shrunk.cache_hits} cache hits, {shrunk.rounds} rounds, "
          f"{shrunk.seconds:.1f} s; budget {BUDGET} simulations -> ratio {shrunk.simulations / BUDGET:.2f}")
    figures_json.write(args.json, {
        "faults_before": len(spec.faults), "faults_after": kept, "simulations": shrunk.simulations,
        "cache_hits": shrunk.cache_hits, "rounds": shrunk.rounds, "seconds": shrunk.seconds,
        "budget_simulations": BUDGET, "ratio_to_budget": shrunk.simulations / BUDGET})


if __name__ == "__main__":
    main()
