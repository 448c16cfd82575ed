"""Coordinator memory at the end of a sweep: writing summary.json, runs.csv and
latency.json (`reporting.write_tables`) for 1,000 and for 10,000 stored runs.

    python benchmarks/bench_tables_memory.py [--small 1000] [--large 10000] [--json FILE]

Synthetic runs (no simulation: `RunResult`s of a 2-axis grid sweep with three oracles,
classified, with latency stats) are committed to a SQLite store; the peak of Python's traced
memory (tracemalloc) while the tables are written is measured for each store, and the
growth per run between the two sizes is printed (target: flat, i.e. about 0 B per run).
For comparison it also measures building the whole runs DataFrame in memory
(`runs_table(...).to_csv`, what the CSV writer did before it streamed). Both sizes must
exceed the writer's chunk (`reporting.summary.CHUNK_RUNS` rows): below it a store's whole
table is one chunk, and memory grows up to that size by design.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import _figures as figures_json  # benchmarks/ is on the path when run as a script

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

SCENARIO = """
scenario tables {{
  duration 1 s
  road r {{
    line length 200 m
    lanes right 1 width 3.5 m
  }}
  param gap = 20 m in [0 m, 1000 m]
  param speed = 10 m/s in [1 m/s, 40 m/s]
  ego car on r lane -1 at 10 m speed speed {{
    stack bev
  }}
  expect {{
    no collision
    moving: always ego.speed > 1 m/s
    warn max jerk 10 m/s^3
  }}
  sweep {{
    grid gap in [{gaps}] m
    grid speed in [10, 20] m/s
    repeat {repeat}
  }}
}}
"""


def build_store(directory: Path, runs: int):
    from addt_dsl.compiler import compile_source
    from addt_dsl.runtime.result import RunResult, Verdict
    from addt_dsl.runtime.store import ResultStore
    from addt_dsl.sweep import expand

    cells = 50  # 50 gaps x 2 speeds
    repeat = max(1, runs // (2 * cells))
    result = compile_source(SCENARIO.format(gaps=", ".join(str(10 + 5 * i) for i in range(cells)),
                                            repeat=repeat))
    assert result.ok, result.diagnostics
    plan = result.plan
    store = ResultStore(directory / f"r{runs}.sqlite", plan)
    outcomes = ("masked", "silent", "detected", "hazard")
    for i, spec in enumerate(expand(plan).specs[:runs]):
        r = RunResult.unfinished(spec, "ok", "", 1.0, seq=i, worker="w")
        r.verdicts = [Verdict("no_collision", "hard", 0.5, True),
                      Verdict("moving", "hard", 1.0 - (i % 7) / 3, i % 7 < 3, None if i % 7 < 3 else 0.25),
                      Verdict("max_jerk", "warn", -0.1, False, 0.5)]
        r.outcome = outcomes[i % 4]
        r.fault_events = i % 3
        r.stats = {"latency_hist": {"e2e": {"3": 10, "60": 2}}, "latency_max_s": {"e2e": 0.121},
                   "e2e_by_objects": {"2": [12, 0.5, 0.121]}}
        store.add(r)
    return store


def peak_bytes(fn) -> int:
    tracemalloc.start()
    tracemalloc.reset_peak()
    base = tracemalloc.get_traced_memory()[0]
    fn()
    peak = tracemalloc.get_traced_memory()[1] - base
    tracemalloc.stop()
    return peak


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--small", type=int, default=1000)
    ap.add_argument("--large", type=int, default=10_000)
    ap.add_argument("--json", help="also write the figures here")
    args = ap.parse_args()
    from addt_dsl.reporting import runs_table, write_tables
    from addt_dsl.reporting.summary import CHUNK_RUNS

    if args.small < CHUNK_RUNS:
        print(f"note: --small {args.small} is under the {CHUNK_RUNS}-row chunk: the growth includes filling it")

    tmp = Path(tempfile.mkdtemp(prefix="addt-tables-"))
    figures = {}
    try:
        stores = {}
        for n in (args.small, args.large):
            t0 = time.perf_counter()
            stores[n] = build_store(tmp, n)
            print(f"store of {len(stores[n])} synthetic runs built in {time.perf_counter() - t0:.1f} s")
        for n, store in stores.items():
            write_tables(tmp / f"warm{n}", store)  # imports and caches outside the measurement
        peaks, whole = {}, {}
        for n, store in stores.items():
            t0 = time.perf_counter()
            peaks[n] = peak_bytes(lambda s=store, n=n: write_tables(tmp / f"out{n}", s))
            elapsed = time.perf_counter() - t0
            whole[n] = peak_bytes(lambda s=store, n=n: runs_table(s.plan(), s.records()).to_csv(tmp / f"whole{n}.csv"))
            print(f"{n:>6} runs: write_tables peak {peaks[n] / 1024:8.0f} kB ({elapsed:.1f} s under tracemalloc); "
                  f"whole runs DataFrame peak {whole[n] / 1024:8.0f} kB")
        span = args.large - args.small
        growth = (peaks[args.large] - peaks[args.small]) / span
        growth_whole = (whole[args.large] - whole[args.small]) / span
        print(f"growth per run, {args.small} -> {args.large} runs: write_tables {growth:+.1f} B/run "
              f"(streamed), whole DataFrame {growth_whole:+.0f} B/run")
        print(f"target: flat, under 10 B/run (the unstreamed tables took +1.9 kB/run): "
              f"ratio to target {growth / 10:.2f}; "
              f"to the whole-DataFrame growth {growth / growth_whole:.3f}")
        print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores (memory figures do not depend on it)")
        figures = {"small": args.small, "large": args.large, "peak_small_B": peaks[args.small],
                   "peak_large_B": peaks[args.large], "growth_B_per_run": growth,
                   "whole_dataframe_growth_B_per_run": growth_whole}
        for s in stores.values():
            s.close()
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    figures_json.write(args.json, figures)
    return 0


if __name__ == "__main__":
    sys.exit(main())
