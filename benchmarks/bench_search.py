"""Guided search vs uniform random sampling: runs needed to the first failure.

    PYTHONPATH=. python benchmarks/bench_search.py [--scenarios FILE ...] [--samplers random bo]
        [--seeds 20] [--budget 150] [--batch 8] [--jobs 2]

The suite (default): the scenarios in `examples/search/`, each written so that a
failure needs several things at once (a small failure region: uniform sampling fails
under 3 % of runs; `examples/lead_brake.addt` no longer fails at all since the stack
brakes for emergencies, so it left the suite). Every sampler searches the same
space (`addt_dsl.search.falsify.SearchSpace`: parameters, fault presence, times and
magnitudes) with the same budget and seeds; `random` is uniform sampling. A seed that
finds no failure within the budget counts as budget + 1 runs (censored; reported).

Prints per scenario the median and mean runs to the first failure per sampler, the ratio
random / sampler of the medians (> 1: the guided search needs fewer runs), the uniform
failure rate estimated from the random sampler's runs (failures per run over all seeds,
with a 95 % Wilson interval: each seed's runs up to and including its first failure),
and the wall time per sampler (the model's fitting included). The suite figure is the
median over scenarios of the per-scenario median ratios.
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
from addt_dsl.runtime.outcome import wilson_interval  # noqa: E402
from addt_dsl.search.falsify import SAMPLERS, Falsifier  # noqa: E402

SUITE = sorted((ROOT / "examples" / "search").glob("*.addt"))


def first_failure(plan, sampler: str, seed: int, budget: int, batch: int, jobs: int) -> tuple[int, bool, float]:
    t0 = time.perf_counter()
    report = Falsifier(plan, seed=seed, batch=batch, jobs=jobs, sampler=sampler).run(
        budget_runs=budget, shrink_simulations=0, stop_at_first=True)
    found = report.first_failure_run is not None
    return (report.first_failure_run if found else budget + 1), found, time.perf_counter() - t0


def bench_scenario(path: Path, samplers: list[str], seeds: int, budget: int, batch: int, jobs: int) -> dict:
    plan = compile_file(path).plan
    rows: dict[str, list[tuple[int, bool]]] = {s: [] for s in samplers}
    seconds = {s: 0.0 for s in samplers}
    print(f"\n{plan.name} ({path.relative_to(ROOT)}): budget {budget} runs, {seeds} seeds")
    print(f"{'seed':>4}  " + "  ".join(f"{s:>7}" for s in samplers))
    for seed in range(seeds):
        cells = []
        for sampler in samplers:
            runs, found, secs = first_failure(plan, sampler, seed, budget, batch, jobs)
            rows[sampler].append((runs, found))
            seconds[sampler] += secs
            cells.append(f"{runs:>6}{'' if found else '+'}")
        print(f"{seed:>4}  " + "  ".join(f"{c:>7}" for c in cells), flush=True)
    out: dict = {"scenario": plan.name, "file": str(path.relative_to(ROOT))}
    for sampler, r in rows.items():
        runs = [n for n, _ in r]
        out[sampler] = {"median_runs_to_failure": statistics.median(runs), "mean_runs_to_failure": statistics.mean(runs),
                        "censored": sum(not f for _, f in r), "wall_s": seconds[sampler]}
        print(f"{sampler:>7}: median {statistics.median(runs):.1f} runs, mean {statistics.mean(runs):.1f}, "
              f"censored {out[sampler]['censored']}/{len(r)}, {seconds[sampler]:.0f} s")
    if "random" in rows:
        failures = sum(f for _, f in rows["random"])
        runs = sum(n if f else n - 1 for n, f in rows["random"])
        lo, hi = wilson_interval(failures, runs)
        out["uniform_failure_rate"] = {"estimate": failures / runs if runs else None, "ci95": [lo, hi]}
        print(f"uniform failure rate: {100 * failures / runs:.2f} % (95 % CI {100 * lo:.2f}-{100 * hi:.2f} %, "
              f"{failures} failures in {runs} random runs)")
        for sampler in samplers:
            if sampler != "random":
                ratio = out["random"]["median_runs_to_failure"] / out[sampler]["median_runs_to_failure"]
                out[sampler]["ratio_random_median"] = ratio
                print(f"ratio random/{sampler} (medians): {ratio:.2f}")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", nargs="*", type=Path, default=SUITE)
    ap.add_argument("--samplers", nargs="+", choices=SAMPLERS, default=["random", "bo"])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--budget", type=int, default=150)
    ap.add_argument("--batch", type=int, default=8, help="candidates per generation of cem and random")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--json", help="also write the figures here")
    args = ap.parse_args()
    results = [bench_scenario(p.resolve(), args.samplers, args.seeds, args.budget, args.batch, args.jobs)
               for p in args.scenarios]
    figures: dict = {"budget_runs": args.budget, "seeds": args.seeds, "samplers": args.samplers, "scenarios": results}
    print()
    for sampler in args.samplers:
        ratios = [r[sampler]["ratio_random_median"] for r in results if "ratio_random_median" in r.get(sampler, {})]
        if ratios:
            figures[f"suite_ratio_random_to_{sampler}"] = statistics.median(ratios)
            print(f"suite: random/{sampler} median of per-scenario median ratios {statistics.median(ratios):.2f} "
                  f"(per scenario: {', '.join(f'{x:.2f}' for x in ratios)}; lowest {min(ratios):.2f})")
    figures_json.write(args.json, figures)


if __name__ == "__main__":
    main()
