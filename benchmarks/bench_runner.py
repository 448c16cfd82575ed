"""Runner benchmark: sweep throughput and coordinator memory.

1. Throughput: runs per minute of a 200-run sweep of a short closed-loop scenario (3 s
   simulated, one agent, lidar with drops) on 1 and on 2 local workers, and the scaling
   ratio. Every run is committed to a SQLite store, as in `addtc`. With Ray installed, the
   same sweep on a local Ray cluster of 2 CPUs (`--executor ray`): its start-up (`ray.init`)
   and its throughput against the local executor's at 2 workers (Ray's per-task overhead).
2. Coordinator memory: resident memory of the coordinating process while it walks a
   10,000-run sweep of a trivial scenario (0.1 s, no agents, no sensors), sampled every
   1,000 runs, and its peak. Flat means the coordinator keeps nothing per run beyond the
   store: RunSpecs are streamed and share one plan, results go to SQLite.
3. Dispatch (`--dispatch-only` for this part alone): the local executor's cost per run
   beside the run, from no-op runs (a run function that returns a record at once) on 1 and
   2 warm workers, at batch 1 and 8, minus the same runs in this process (inline); runs
   sharing one plan (a sweep) and each with its own (a search's candidates); the start of 2
   workers; then 16 short closed-loop runs inline, on 1 and on 2 workers (the session's CPU
   share decides whether 2 workers are faster: the load average is printed beside).

Each part runs in a fresh interpreter so one part's peak does not hide the other's.

Run: PYTHONPATH=. python benchmarks/bench_runner.py [--runs 200] [--memory-runs 10000] [--dispatch-only]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import _figures as figures_json

SHORT = """
scenario short {
  duration 3 s
  road r {
    line length 300 m
    lanes right 2 width 3.5 m
  }
  param drop = 5 % in [0 %, 50 %]
  ego car on r lane -1 at 20 m speed 20 m/s {
    stack bev cruise_speed 20 m/s
    sensor lidar rate 10 Hz rays 180 range 60 m
  }
  agent lead car on r lane -2 at 60 m speed 15 m/s {
    behavior cruise speed 15 m/s
  }
  faults {
    drop lidar rate drop
  }
  expect {
    no collision
    always abs(lane_offset(ego)) < 1.8 m
  }
  sweep {
    grid drop in [0, 10] %
    repeat REPEAT
  }
}
"""

TRIVIAL = """
scenario trivial {
  duration 0.1 s
  road r {
    line length 200 m
    lanes right 1 width 3.5 m
  }
  ego car on r lane -1 at 10 m speed 10 m/s {
    stack bev
  }
  expect {
    moving: always ego.speed > 1 m/s
  }
  sweep {
    repeat REPEAT
  }
}
"""


def _plan(text: str, repeat: int):
    from addt_dsl.compiler import compile_source

    result = compile_source(text.replace("REPEAT", str(repeat)))
    assert result.ok, result.diagnostics
    return result.plan


def _rss_mb() -> float:
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def part_throughput(runs: int, jobs: int, executor_name: str = "local") -> dict:
    from addt_dsl.reporting.summary import store_summary
    from addt_dsl.runtime.executor import LocalExecutor, run_sweep
    from addt_dsl.runtime.store import ResultStore
    from addt_dsl.sweep import SweepStream

    plan = _plan(SHORT, runs // 2)
    init_s = 0.0
    if executor_name == "ray":
        import ray

        from addt_dsl.runtime.ray_executor import RayExecutor

        t0 = time.perf_counter()
        ray.init(num_cpus=jobs, include_dashboard=False, log_to_driver=False)
        init_s = time.perf_counter() - t0
        executor = RayExecutor(jobs=jobs)
    else:
        executor = LocalExecutor(jobs)
    with tempfile.TemporaryDirectory() as tmp, ResultStore(Path(tmp) / "r.sqlite", plan) as store:
        t0, cpu0 = time.perf_counter(), time.process_time()
        outcome = run_sweep(SweepStream(plan), store, executor)
        wall, cpu = time.perf_counter() - t0, time.process_time() - cpu0
        sim = store_summary(store)["sim_time_s"]
    return {"executor": executor_name, "jobs": jobs, "runs": outcome.ran, "wall_s": wall,
            "runs_per_min": 60 * outcome.ran / wall, "sim_s_per_wall_s": sim / wall,
            "coordinator_cpu_ms_per_run": 1e3 * cpu / outcome.ran, "init_s": init_s,
            "load": [round(x, 2) for x in os.getloadavg()]}


def part_memory(runs: int, jobs: int) -> dict:
    from addt_dsl.runtime.executor import LocalExecutor, run_sweep
    from addt_dsl.runtime.store import ResultStore
    from addt_dsl.sweep import SweepStream

    plan = _plan(TRIVIAL, runs)
    samples: list[tuple[int, float]] = [(0, _rss_mb())]
    count = 0

    def on_record(_record) -> None:
        nonlocal count
        count += 1
        if count % 1000 == 0:
            samples.append((count, _rss_mb()))

    with tempfile.TemporaryDirectory() as tmp, ResultStore(Path(tmp) / "r.sqlite", plan) as store:
        t0 = time.perf_counter()
        run_sweep(SweepStream(plan), store, LocalExecutor(jobs), on_record=on_record)
        wall = time.perf_counter() - t0
        stored = len(store)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    # For contrast: the same sweep expanded eagerly into a list.
    import tracemalloc

    from addt_dsl.sweep import expand

    tracemalloc.start()
    specs = expand(plan).specs
    list_mb = tracemalloc.get_traced_memory()[0] / 2**20
    tracemalloc.stop()
    del specs
    return {"runs": stored, "wall_s": wall, "samples": samples, "peak_rss_mb": peak, "eager_list_mb": list_mb}


def _noop_run(spec, seq: int = -1, worker: str = ""):
    """A run that does nothing: what is left of its wall time is the executor's."""
    from addt_dsl.runtime.result import RunResult

    return RunResult.unfinished(spec, "ok", "", 0.0, seq=seq, worker=worker)


def part_dispatch(runs: int) -> dict:
    from addt_dsl.runtime.executor import InlineExecutor, LocalExecutor

    plan = _plan(SHORT, max(1, runs // 2))
    from addt_dsl.sweep import expand

    shared = expand(plan).specs[:runs]
    # A search's candidates: each its own plan object (sent to a worker with its run).
    own = [s.model_copy(update={"plan": plan.model_copy(deep=True)}) for s in shared]

    def wall(executor, specs) -> float:
        t0 = time.perf_counter()
        records = list(executor.imap(enumerate(specs)))
        assert len(records) == len(specs) and all(r.status == "ok" for r in records)
        return time.perf_counter() - t0

    out: dict = {"runs": len(shared)}
    for label, specs in (("one_plan", shared), ("own_plans", own)):
        inline = InlineExecutor(_noop_run, timeout_s=None, memory_limit_mb=None)
        wall(inline, specs[:4])
        base = min(wall(inline, specs) for _ in range(3))
        out[f"{label}_inline_ms"] = 1e3 * base / len(specs)
        for jobs, batch in ((1, 1), (2, 1), (2, 8)):
            executor = LocalExecutor(jobs, run_fn=_noop_run, keep_workers=True, batch=batch)
            try:
                wall(executor, specs[:2 * jobs])  # workers started: not timed
                t = min(wall(executor, specs) for _ in range(3))
            finally:
                executor.close()
            out[f"{label}_jobs{jobs}_batch{batch}_ms"] = 1e3 * (t - base) / len(specs)
    starts = []
    for _ in range(3):
        executor = LocalExecutor(2, run_fn=_noop_run)
        starts.append(wall(executor, shared[:2]))
    out["start_2_workers_ms"] = 1e3 * min(starts)
    short = shared[:16]
    out["short_runs"] = len(short)
    executors = {"inline": lambda: InlineExecutor(), "jobs1": lambda: LocalExecutor(1),
                 "jobs2": lambda: LocalExecutor(2)}
    for name, make in executors.items():
        out[f"short_{name}_s"] = wall(make(), short)
    out["load"] = [round(x, 2) for x in os.getloadavg()]
    return out


def _print_dispatch(d: dict) -> None:
    print(f"Dispatch: per-run cost of the local executor [ms] beside the run (no-op runs, {d['runs']} a "
          "measurement, best of 3, minus inline)")
    for label, what in (("one_plan", "runs of one plan (a sweep)"), ("own_plans", "each its own plan (a search)")):
        print(f"  {what}: inline {d[f'{label}_inline_ms']:.2f} ms/run itself; local executor "
              f"{d[f'{label}_jobs1_batch1_ms']:+.2f} ms/run on 1 worker, {d[f'{label}_jobs2_batch1_ms']:+.2f} on 2, "
              f"{d[f'{label}_jobs2_batch8_ms']:+.2f} on 2 at batch 8")
    print(f"  starting 2 workers (forkserver running) and 2 no-op runs: {d['start_2_workers_ms']:.0f} ms")
    print(f"  {d['short_runs']} short closed-loop runs (3 s simulated): inline {d['short_inline_s']:.2f} s, "
          f"1 worker {d['short_jobs1_s']:.2f} s, 2 workers {d['short_jobs2_s']:.2f} s "
          f"(load average {', '.join(f'{x:.1f}' for x in d['load'])})")


def _in_subprocess(part: str, runs: int, jobs: int, executor: str = "local") -> dict:
    out = subprocess.run([sys.executable, __file__, "--part", part, "--runs", str(runs), "--jobs", str(jobs),
                          "--executor", executor], capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--runs", type=int, default=200)
    parser.add_argument("--memory-runs", type=int, default=10_000)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--part", choices=("throughput", "memory", "dispatch"))
    parser.add_argument("--dispatch-runs", type=int, default=200)
    parser.add_argument("--dispatch-only", action="store_true", help="only the dispatch part")
    parser.add_argument("--executor", choices=("local", "ray"), default="local")
    parser.add_argument("--no-ray", action="store_true", help="skip the Ray comparison")
    parser.add_argument("--json", help="also write the figures here")
    args = parser.parse_args()
    if args.part == "throughput":
        print(json.dumps(part_throughput(args.runs, args.jobs, args.executor)))
        return
    if args.part == "memory":
        print(json.dumps(part_memory(args.runs, args.jobs)))
        return
    if args.part == "dispatch":
        print(json.dumps(part_dispatch(args.runs)))
        return
    if args.dispatch_only:
        print(f"load average before: {', '.join(f'{x:.1f}' for x in os.getloadavg())} on {os.cpu_count()} CPUs")
        d = _in_subprocess("dispatch", args.dispatch_runs, 2)
        _print_dispatch(d)
        figures_json.write(args.json, {"dispatch": d})
        return

    print(f"load average before: {', '.join(f'{x:.1f}' for x in os.getloadavg())} on {os.cpu_count()} CPUs "
          "(other processes compete for the workers' CPUs)")
    print(f"Throughput: {args.runs}-run sweep of a 3 s scenario (1 agent, lidar, drop faults), SQLite store")
    results = {}
    for jobs in (1, 2):
        r = results[jobs] = _in_subprocess("throughput", args.runs, jobs)
        print(f"  {jobs} worker(s): {r['runs']} runs in {r['wall_s']:.1f} s = {r['runs_per_min']:.0f} runs/min "
              f"({r['sim_s_per_wall_s']:.0f}x real time; coordinator CPU {r['coordinator_cpu_ms_per_run']:.1f} ms/run)")
    print(f"  scaling 2 vs 1 workers: {results[2]['runs_per_min'] / results[1]['runs_per_min']:.2f}x "
          f"(machine has {os.cpu_count()} CPUs; load average during each part: "
          f"{results[1]['load'][0]:.1f}, {results[2]['load'][0]:.1f})")
    ray_figures = None
    if args.no_ray:
        pass
    elif importlib.util.find_spec("ray") is None:
        print("  Ray: not installed (pip install 'addt-dsl[ray]'), comparison skipped")
    else:
        ray_figures = _in_subprocess("throughput", args.runs, 2, "ray")
        local2 = results[2]
        print(f"  Ray, local cluster of 2 CPUs: {ray_figures['runs']} runs in {ray_figures['wall_s']:.1f} s = "
              f"{ray_figures['runs_per_min']:.0f} runs/min after {ray_figures['init_s']:.1f} s of ray.init; "
              f"throughput vs the local executor at 2 workers: "
              f"{ray_figures['runs_per_min'] / local2['runs_per_min']:.2f}x, per-run overhead "
              f"{1e3 * (ray_figures['wall_s'] - local2['wall_s']) / ray_figures['runs']:+.1f} ms "
              f"(load average {ray_figures['load'][0]:.1f})")

    print(f"load average: {', '.join(f'{x:.1f}' for x in os.getloadavg())}")
    print(f"Coordinator memory: {args.memory_runs}-run sweep of a trivial scenario on {args.jobs} workers")
    m = _in_subprocess("memory", args.memory_runs, args.jobs)
    print(f"  {m['runs']} runs stored in {m['wall_s']:.1f} s ({60 * m['runs'] / m['wall_s']:.0f} runs/min)")
    print("  coordinator RSS [MB] by runs done: "
          + ", ".join(f"{n}: {mb:.1f}" for n, mb in m["samples"]))
    first = next((mb for n, mb in m["samples"] if n >= 1000), m["samples"][0][1])
    last = m["samples"][-1][1]
    print(f"  growth from 1,000 to {m['samples'][-1][0]:,} runs: {last - first:+.1f} MB; "
          f"peak RSS {m['peak_rss_mb']:.1f} MB")
    print(f"  (for contrast, the same {m['runs']} RunSpecs held as a list: {m['eager_list_mb']:.1f} MB)")
    d = _in_subprocess("dispatch", args.dispatch_runs, 2)
    _print_dispatch(d)
    figures_json.write(args.json, {
        "dispatch": d,
        "throughput": {str(j): r for j, r in results.items()},
        "scaling_2_vs_1": results[2]["runs_per_min"] / results[1]["runs_per_min"],
        "ray": ray_figures,
        "memory": {**m, "growth_mb_from_1000_runs": last - first}})


if __name__ == "__main__":
    main()
