"""Throughput of the engine over batches (`execute_batch`): simulated seconds per wall
second (and per CPU second of the process) for the same runs stepped one at a time and in
batches, in one process on one core; the peak memory of each batch.

Run: PYTHONPATH=. python benchmarks/bench_batch.py [--quick] [--json FILE] [--profile B]
     [--scaling | --scaling-only] [--versus CHECKOUT [--rounds N]]

- a ground-truth sweep: `examples/overtake.addt` (30 s, lidar, bev stack, drop faults) with
  64 runs (its grid cells, each repeated with other seeds), at batch 1, 16 and 64;
- 50 IDM agents (`bench_twin.traffic_source(50)`, 5 s): one run, and 16 runs at batch 16;
- `--scaling`: agents 1/5/20/50/100 x batch 1/16/64/256 (1 s runs, 16 runs or one batch);
- `--profile B`: cProfile's top functions of the ground-truth sweep at batch B instead;
- `--versus CHECKOUT`: each configuration in this checkout and in another one (e.g. a
  worktree of an older commit), alternating, `--rounds` times (default 2), the best of each;
  the ratio this / other per configuration (> 1: this checkout is faster).

Each configuration runs in a fresh process (its peak RSS is its own); ratios are to batch 1
of the same workload, measured in this one invocation, with the load average beside.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import _figures as figures_json  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
QUICK = "--quick" in sys.argv
JSON_PATH = sys.argv[sys.argv.index("--json") + 1] if "--json" in sys.argv else None
# Batch sizes of the scaling table (a traffic run without a pybullet client holds a few MB
# until its batch ends: 256 of them fit a shared machine; docs/twin.md, Batches).
SCALING_BATCHES = (1, 16, 64, 256)
VERSUS_BATCHES = (1, 16, 64)  # `--versus`: an older checkout's runs held ~40 MB each (256: ~11 GB)


def overtake_specs(n: int) -> list:
    """`n` runs of the overtake example: its cells, repeated with other seeds."""
    from addt_dsl.compiler import compile_file
    from addt_dsl.sweep import expand

    base = expand(compile_file(ROOT / "examples" / "overtake.addt").plan).specs
    out = []
    for i in range(n):
        s = base[i % len(base)]
        out.append(s.model_copy(update={"seed": s.seed + 1000 * (i // len(base)), "run_id": f"r{i:03d}"}))
    return out


def traffic_specs(n_agents: int, n: int, duration: float) -> list:
    from bench_twin import compile_spec, traffic_source

    spec = compile_spec(traffic_source(n_agents, duration=duration))
    return [spec.model_copy(update={"seed": spec.seed + i, "run_id": f"r{i:03d}"}) for i in range(n)]


def measure(workload: str, runs: int, batch: int, agents: int = 50, duration: float = 5.0) -> dict:
    """In this process: the runs stepped in batches of `batch`; simulated s, wall s, CPU s,
    resident memory before and at its peak."""
    import resource

    from addt_dsl.runtime.execute import execute_batch
    from addt_dsl.runtime.executor import rss_mb

    specs = overtake_specs(runs) if workload == "overtake" else traffic_specs(agents, runs, duration)
    execute_batch(specs[:1])  # imports, caches, the stack's first-use work: not timed
    base_mb = rss_mb(os.getpid())
    wall0, cpu0 = time.perf_counter(), time.process_time()
    sim = 0.0
    for i in range(0, len(specs), batch):
        sim += sum(r.sim_time_s for r in execute_batch(specs[i:i + batch], keep_trace=False))
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    return {"runs": runs, "batch": batch, "sim_s": sim, "wall_s": wall, "cpu_s": cpu,
            "sim_per_wall": sim / wall, "sim_per_cpu": sim / cpu, "base_rss_mb": base_mb, "peak_rss_mb": peak_mb,
            "rss_per_run_mb": (peak_mb - base_mb) / batch}


def in_child(root: Path = ROOT, **kw) -> dict:
    """`measure(**kw)` in a fresh process of the checkout at `root` (this script's code,
    that checkout's package)."""
    env = dict(os.environ, PYTHONPATH=f"{root}{os.pathsep}{ROOT / 'benchmarks'}", OMP_NUM_THREADS="1")
    out = subprocess.run([sys.executable, __file__, "--child", json.dumps(kw)], env=env, cwd=root,
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def versus(other: Path, rounds: int) -> dict:
    """The configurations in this checkout and `other`, alternating; the best of `rounds`."""
    configs = [dict(workload="overtake", runs=16, batch=b) for b in (1, 16)]
    configs += [dict(workload="traffic", runs=1, batch=1, agents=50)]
    configs += [dict(workload="traffic", runs=max(16, b), batch=b, agents=a, duration=1.0)
                for a in (1, 5, 20, 50, 100) for b in VERSUS_BATCHES]
    print(f"load average before: {', '.join(f'{x:.2f}' for x in os.getloadavg())}; this = {ROOT}, other = {other}")
    print(f"{'':34s} {'this':>9s} {'other':>9s}  sim-s per CPU-s, best of {rounds}; ratio this / other")
    figures = {}
    for kw in configs:
        best = {"this": 0.0, "other": 0.0}
        for _ in range(rounds):
            for name, root in (("this", ROOT), ("other", other)):
                best[name] = max(best[name], in_child(root, **kw)["sim_per_cpu"])
        label = (f"overtake x{kw['runs']}, batch {kw['batch']}" if kw["workload"] == "overtake" else
                 f"{kw['agents']} agents x{kw['runs']}, batch {kw['batch']}")
        figures[label] = {**best, "ratio": best["this"] / best["other"]}
        load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
        print(f"{label:34s} {best['this']:9.1f} {best['other']:9.1f}  {best['this'] / best['other']:5.2f}x  "
              f"load {load}", flush=True)
    return figures


def row(label: str, m: dict, ref: dict | None) -> str:
    ratio = "" if ref is None else \
        f"{m['sim_per_wall'] / ref['sim_per_wall']:5.2f}x {m['sim_per_cpu'] / ref['sim_per_cpu']:5.2f}x"
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    return (f"{label:34s} {m['sim_per_wall']:9.1f} {m['sim_per_cpu']:9.1f}  {ratio:13s} "
            f"{m['peak_rss_mb']:7.0f} {m['rss_per_run_mb']:7.1f}  load {load}")


def profile(batch: int) -> None:
    import cProfile
    import pstats

    from addt_dsl.runtime.execute import execute_batch

    specs = overtake_specs(batch if not QUICK else 4)
    execute_batch(specs[:1])
    prof = cProfile.Profile()
    prof.enable()
    execute_batch(specs, keep_trace=False)
    prof.disable()
    pstats.Stats(prof).sort_stats("tottime").print_stats(25)


def main() -> None:
    if "--scaling-only" in sys.argv:
        sys.argv.append("--scaling")
    if "--child" in sys.argv:
        print(json.dumps(measure(**json.loads(sys.argv[sys.argv.index("--child") + 1]))))
        return
    if "--profile" in sys.argv:
        profile(int(sys.argv[sys.argv.index("--profile") + 1]))
        return
    if "--versus" in sys.argv:
        rounds = int(sys.argv[sys.argv.index("--rounds") + 1]) if "--rounds" in sys.argv else 2
        figures_json.write(JSON_PATH, versus(Path(sys.argv[sys.argv.index("--versus") + 1]).resolve(), rounds))
        return
    print(f"load average before: {', '.join(f'{x:.2f}' for x in os.getloadavg())} on {os.cpu_count()} CPUs")
    print(f"{'':34s} {'sim/wall':>9s} {'sim/cpu':>9s}  {'ratio w / cpu':13s} {'peak MB':>7s} {'MB/run':>7s}")
    figures: dict = {"overtake": {}, "idm50": {}, "scaling": {}}
    runs = 16 if QUICK else 64
    ref = None
    for batch in () if "--scaling-only" in sys.argv else ((1, 16) if QUICK else (1, 16, 64)):
        m = figures["overtake"][batch] = in_child(workload="overtake", runs=runs, batch=batch)
        print(row(f"overtake x{runs}, batch {batch}", m, ref), flush=True)
        ref = ref or m
    for batch in () if "--scaling-only" in sys.argv else ("one", 1, 16):
        if batch == "one":
            one = figures["idm50"]["one"] = in_child(workload="traffic", runs=1, batch=1, agents=50)
            print(row("50 IDM agents, one run", one, None), flush=True)
            continue
        m = figures["idm50"][batch] = in_child(workload="traffic", runs=16, batch=batch, agents=50)
        print(row(f"50 IDM agents x16, batch {batch}", m, figures["idm50"][1]), flush=True)
    if "--scaling" in sys.argv:
        for agents in (1, 5, 20, 50, 100):
            ref = None
            for batch in SCALING_BATCHES:
                m = figures["scaling"][f"{agents}x{batch}"] = in_child(workload="traffic", runs=max(16, batch),
                                                                      batch=batch, agents=agents, duration=1.0)
                m["agent_s_per_wall"] = m["sim_per_wall"] * agents
                print(row(f"{agents} agents, batch {batch}", m, ref), flush=True)
                ref = ref or m
    figures_json.write(JSON_PATH, figures)


if __name__ == "__main__":
    main()
