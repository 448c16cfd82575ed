"""Guided search vs uniform random sampling: runs needed to the first failure, distinct failures.

    PYTHONPATH=. python benchmarks/bench_search.py [--scenarios FILE ...] [--samplers random bo]
        [--seeds 20] [--budget 150] [--random-budget 300] [--batch 8] [--jobs 2] [--cache DIR]
        [--distinct-seeds 2] [--distinct-budget 100] [--distinct-shrink 20]
    PYTHONPATH=. python benchmarks/bench_search.py --throughput 32 [--samplers random bo] [--jobs 1]

The suite (default): the scenarios in `examples/search/`, each written so that a
failure needs several things at once (a small failure region: uniform sampling fails
under 3 % of runs; `examples/lead_brake.addt` left the suite when the stack began to
brake for emergencies: its collisions became rare, the Bayesian search's seed 0 needs
104-134 runs). Schedules of several declared faults, one or two of which matter, are in
`examples/search/many_faults/` (pass them with `--scenarios`; `--samplers random bo bandit`
compares the bandit over which fault is present). Every sampler searches the same
space (`addt_dsl.search.space.SearchSpace`: parameters, fault presence, times and
magnitudes) with the same budget and seeds; `random` is uniform sampling over that space
(`UniformSampler`). A seed that finds no failure within the budget counts as budget + 1
runs (censored; reported: a censored median is a lower bound). `--random-budget` gives
uniform sampling a larger budget than the guided samplers (default: the same), so that
its median on a small failure region is measured rather than censored.

Prints per scenario the median and mean runs to the first failure per sampler, the ratio
random / sampler of the medians (> 1: the guided search needs fewer runs), the uniform
failure rate estimated from the random sampler's runs (failures per run over all seeds,
with a 95 % Wilson interval: each seed's runs up to and including its first failure),
what that rate implies for uniform sampling's median (ln 2 / p: runs to the
first failure are geometric), the wall time per sampler (the model's fitting included; the machine's load beside it),
and, from `--distinct-seeds` whole searches of `--distinct-budget` runs with shrinking,
distinct failures per 1,000 runs (search and shrink runs both count) and failing search
runs per 1,000. Then one table of all scenarios; the suite figure is the median over
scenarios of the per-scenario median ratios.

`--throughput N` measures instead falsification runs per wall second (searches of N runs)
with the run cache stepping each call's misses one by one against together (the batch
engine), and prints the ratio with the load beside it.

`--cache DIR` keeps every run in `DIR/<scenario file>.sqlite` (the search's run cache):
runs are pure functions of their RunSpec, so a killed benchmark run again replays what it
has and goes on, and the counts do not change.
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import _figures as figures_json  # noqa: E402
from addt_dsl.compiler import compile_file  # noqa: E402
from addt_dsl.runtime.outcome import wilson_interval  # noqa: E402
from addt_dsl.search.cache import RunCache  # noqa: E402
from addt_dsl.search.falsify import Falsifier  # noqa: E402
from addt_dsl.search.samplers import SAMPLERS  # noqa: E402

SUITE = sorted((ROOT / "examples" / "search").glob("*.addt"))


def budget_of(sampler: str, args) -> int:
    return args.random_budget if sampler == "random" and args.random_budget else args.budget


def first_failure(plan, sampler: str, seed: int, args, cache: RunCache) -> tuple[int, bool, float]:
    t0 = time.perf_counter()
    budget = budget_of(sampler, args)
    report = Falsifier(plan, seed=seed, batch=args.batch, jobs=args.jobs, sampler=sampler, cache=cache).run(
        budget_runs=budget, shrink_simulations=0, stop_at_first=True)
    found = report.first_failure_run is not None
    return (report.first_failure_run if found else budget + 1), found, time.perf_counter() - t0


def distinct_failures(plan, sampler: str, args, cache: RunCache) -> dict:
    """Whole searches (no stop at the first failure) with shrinking: distinct failures per 1,000 runs."""
    distinct = runs = search_runs = failing = 0
    for seed in range(args.distinct_seeds):
        report = Falsifier(plan, seed=seed, batch=args.batch, jobs=args.jobs, sampler=sampler, cache=cache).run(
            budget_runs=args.distinct_budget, shrink_simulations=args.distinct_shrink)
        distinct += len(report.failures)
        failing += sum(f.count for f in report.failures)
        search_runs += report.runs
        runs += report.runs + report.shrink_simulations
    return {"searches": args.distinct_seeds, "distinct": distinct, "runs": runs,
            "per_1000_runs": 1000.0 * distinct / runs if runs else 0.0,
            "failing_search_runs_per_1000": 1000.0 * failing / search_runs if search_runs else 0.0}


def bench_scenario(path: Path, args) -> dict:
    plan = compile_file(path).plan
    samplers = args.samplers
    cache = RunCache(args.cache / f"{path.stem}.sqlite" if args.cache else None)
    rows: dict[str, list[tuple[int, bool]]] = {s: [] for s in samplers}
    seconds = {s: 0.0 for s in samplers}
    print(f"\n{plan.name} ({path.relative_to(ROOT)}): budget {args.budget} runs "
          f"(random {budget_of('random', args)}), {args.seeds} seeds, "
          f"load {figures_json.load()}")
    print(f"{'seed':>4}  " + "  ".join(f"{s:>7}" for s in samplers))
    try:
        for seed in range(args.seeds):
            cells = []
            for sampler in samplers:
                runs, found, secs = first_failure(plan, sampler, seed, args, cache)
                rows[sampler].append((runs, found))
                seconds[sampler] += secs
                cells.append(f"{runs:>6}{'' if found else '+'}")
            print(f"{seed:>4}  " + "  ".join(f"{c:>7}" for c in cells), flush=True)
        out: dict = {"scenario": plan.name, "file": str(path.relative_to(ROOT))}
        for sampler, r in rows.items():
            runs = [n for n, _ in r]
            out[sampler] = {"median_runs_to_failure": statistics.median(runs),
                            "mean_runs_to_failure": statistics.mean(runs),
                            "censored": sum(not f for _, f in r), "wall_s": seconds[sampler],
                            "runs_to_failure": runs}
            print(f"{sampler:>7}: median {statistics.median(runs):.1f} runs, mean {statistics.mean(runs):.1f}, "
                  f"censored {out[sampler]['censored']}/{len(r)}, {seconds[sampler]:.0f} s "
                  f"(cache hits included; load {figures_json.load()})")
        if "random" in rows:
            failures = sum(f for _, f in rows["random"])
            runs = sum(n if f else n - 1 for n, f in rows["random"])
            lo, hi = wilson_interval(failures, runs)
            out["uniform_failure_rate"] = {"estimate": failures / runs if runs else None, "ci95": [lo, hi],
                                           "failures": failures, "runs": runs}
            print(f"uniform failure rate: {100 * failures / runs:.2f} % (95 % CI {100 * lo:.2f}-{100 * hi:.2f} %, "
                  f"{failures} failures in {runs} random runs)"
                  + (f"; geometric median ln 2 / p = {math.log(2) * runs / failures:.0f} runs" if failures else ""))
            for sampler in samplers:
                if sampler != "random":
                    ratio = out["random"]["median_runs_to_failure"] / out[sampler]["median_runs_to_failure"]
                    out[sampler]["ratio_random_median"] = ratio
                    print(f"ratio random/{sampler} (medians): {ratio:.2f}")
        if args.distinct_seeds:
            for sampler in samplers:
                d = distinct_failures(plan, sampler, args, cache)
                out[sampler]["distinct_failures"] = d
                print(f"{sampler:>7}: {d['distinct']} distinct failure(s) in {d['searches']} searches of "
                      f"{args.distinct_budget} runs ({d['runs']} runs with shrinking): {d['per_1000_runs']:.1f} "
                      f"per 1,000 runs; {d['failing_search_runs_per_1000']:.0f} failing search runs per 1,000",
                      flush=True)
    finally:
        cache.close()
    return out


def print_table(results: list[dict], samplers: list[str]) -> None:
    guided = [s for s in samplers if s != "random"]
    head = (["scenario", "seeds", "uniform failure rate (95 % CI)", "ln 2 / p", "random"] + guided
            + [f"ratio {s}" for s in guided])
    head += [f"distinct/1,000 {s}" for s in samplers]
    print("\n| " + " | ".join(head) + " |\n|" + " --- |" * len(head))
    for r in results:
        rate = r.get("uniform_failure_rate")
        cells = [f"`{Path(r['file']).stem}`", str(len(r[samplers[0]]["runs_to_failure"])),
                 f"{100 * rate['estimate']:.2f} % ({100 * rate['ci95'][0]:.2f}-{100 * rate['ci95'][1]:.2f} %)"
                 if rate else "-",
                 f"{math.log(2) / rate['estimate']:.0f}" if rate and rate["estimate"] else "-"]
        for s in ["random"] + guided:
            if s in r:
                c = r[s]["censored"]
                cells.append(f"{r[s]['median_runs_to_failure']:.1f}" + (f" ({c} censored)" if c else ""))
            else:
                cells.append("-")
        cells += [f"{r[s]['ratio_random_median']:.2f}" if "ratio_random_median" in r.get(s, {}) else "-"
                  for s in guided]
        cells += [f"{r[s]['distinct_failures']['per_1000_runs']:.1f}" if "distinct_failures" in r.get(s, {}) else "-"
                  for s in samplers]
        print("| " + " | ".join(cells) + " |")


def throughput(paths: list[Path], args) -> dict:
    """Falsification runs per wall second with the run cache's misses run one by one (engine
    batch 1) against the default (each call's misses stepped together: `RunCache(batch=None)`),
    per sampler, the two alternated `--throughput-repeats` times so that the machine's load
    drifts over both alike; fresh in-memory caches (every run simulated)."""
    figures: dict = {}
    for path in paths:
        plan = compile_file(path).plan
        Falsifier(plan, seed=99, batch=args.batch, jobs=args.jobs, sampler="random",
                  cache=RunCache()).run(budget_runs=4, shrink_simulations=0)  # warm-up: imports, first worlds
        for sampler in args.samplers:
            totals = {1: [0, 0.0], None: [0, 0.0]}
            for rep in range(args.throughput_repeats):
                for engine_batch in (1, None):
                    cache = RunCache(batch=engine_batch)
                    t0 = time.perf_counter()
                    report = Falsifier(plan, seed=rep, batch=args.batch, jobs=args.jobs, sampler=sampler,
                                       cache=cache).run(budget_runs=args.throughput, shrink_simulations=0)
                    totals[engine_batch][0] += cache.simulations
                    totals[engine_batch][1] += time.perf_counter() - t0
                    cache.close()
                    assert report.runs == args.throughput
            one, default = (totals[b][0] / totals[b][1] for b in (1, None))
            figures[f"{path.stem}/{sampler}"] = {"runs_per_s_batch1": one, "runs_per_s_default": default,
                                                  "ratio": default / one}
            print(f"{path.stem} {sampler} (generation {args.batch}, jobs {args.jobs}): {one:.2f} runs/s at engine "
                  f"batch 1, {default:.2f} at the default: x{default / one:.2f} (load {figures_json.load()})")
    return figures


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", nargs="*", type=Path, default=SUITE)
    ap.add_argument("--samplers", nargs="+", choices=tuple(SAMPLERS), default=["random", "bo"])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--budget", type=int, default=150)
    ap.add_argument("--random-budget", type=int, default=0, help="budget of the random sampler (0: --budget)")
    ap.add_argument("--batch", type=int, default=8, help="candidates per generation of cem and random")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--cache", type=Path, help="keep runs in DIR/<scenario>.sqlite (resumable)")
    ap.add_argument("--distinct-seeds", type=int, default=2, help="whole searches per sampler (0: skip)")
    ap.add_argument("--distinct-budget", type=int, default=100)
    ap.add_argument("--distinct-shrink", type=int, default=20, help="shrink simulations per failure group")
    ap.add_argument("--json", help="also write the figures here")
    ap.add_argument("--throughput", type=int, default=0,
                    help="only measure falsification runs per wall second at engine batch 1 against the default, "
                         "this many runs per search")
    ap.add_argument("--throughput-repeats", type=int, default=2)
    args = ap.parse_args()
    if args.throughput:
        figures_json.write(args.json, {"throughput": throughput([p.resolve() for p in args.scenarios], args),
                                       "generation": args.batch, "jobs": args.jobs})
        return
    if args.cache:
        args.cache.mkdir(parents=True, exist_ok=True)
    results = [bench_scenario(p.resolve(), args) for p in args.scenarios]
    figures: dict = {"budget_runs": args.budget, "random_budget_runs": budget_of("random", args), "seeds": args.seeds,
                     "samplers": args.samplers, "scenarios": results}
    print()
    for sampler in args.samplers:
        ratios = [r[sampler]["ratio_random_median"] for r in results if "ratio_random_median" in r.get(sampler, {})]
        if ratios:
            figures[f"suite_ratio_random_to_{sampler}"] = statistics.median(ratios)
            print(f"suite: random/{sampler} median of per-scenario median ratios {statistics.median(ratios):.2f} "
                  f"(per scenario: {', '.join(f'{x:.2f}' for x in ratios)}; lowest {min(ratios):.2f})")
    print_table(results, args.samplers)
    figures_json.write(args.json, figures)


if __name__ == "__main__":
    main()
