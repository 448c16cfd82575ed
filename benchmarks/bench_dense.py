"""Dense traffic: real-time factor of the closed loop with 1-100 IDM agents on a 3-lane road.

Run: PYTHONPATH=. python benchmarks/bench_dense.py [--quick] [--json FILE] [--profile N]

For each agent count, the real-time factor (simulated s per CPU s of the process, and per
wall s; best of a few runs: the machine is shared, and CPU time is the steadier of the two
under load) with ground-truth perception (the default one-channel lidar) and
with learned perception (`stack bev perception learned`, the lidar the detector is
trained for), and its ratio to the targets for 50 agents (>= 100x ground truth,
>= 50x learned). The run is single-threaded (torch is limited to one thread here).
`--profile N` prints cProfile's top functions of one N-agent ground-truth run instead.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import _figures as figures_json

ROOT = Path(__file__).resolve().parents[1]
QUICK = "--quick" in sys.argv
JSON_PATH = sys.argv[sys.argv.index("--json") + 1] if "--json" in sys.argv else None
TARGET = {"ground_truth": 100.0, "learned": 50.0}  # real-time factors to reach: 50 agents, one core
GT_LIDAR = "sensor lidar rate 10 Hz rays 360 range 80 m"
LEARNED_LIDAR = "sensor lidar rate 10 Hz rays 360 channels 5 vfov 12 deg range 80 m"


def dense_source(n_agents: int, perception: str = "ground_truth", duration: float = 10.0,
                 ties: bool = False, lane_changes: bool = False) -> str:
    """`n_agents` IDM cars on a 3-lane road, 25 m apart in each lane, ahead of the ego.

    `ties`: agents in pairs at the same station and lane (equal gaps: leader ties);
    `lane_changes`: every fourth agent changes lane after a few seconds (leaders change)."""
    lidar = LEARNED_LIDAR if perception == "learned" else GT_LIDAR
    agents = []
    for i in range(n_agents):
        slot = i // 2 if ties else i
        lane = -1 - slot % 3
        s = 60 + 25 * (slot // 3)
        extra = ""
        if lane_changes and i % 4 == 1:
            to = -2 if lane != -2 else -1
            extra = f"\n    after {1 + i % 3} s behavior lane_change to {to} duration 3 s"
        agents.append(f"  agent a{i} car on r lane {lane} at {s} m speed 20 m/s {{\n"
                      f"    behavior idm speed {18 + i % 5} m/s{extra}\n  }}")
    body = "\n".join(agents)
    return f"""
scenario dense_{n_agents} {{
  duration {duration} s
  road r {{
    line length 1500 m
    arc length 300 m curvature 0.003 /m
    line length 1000 m
    lanes right 3 width 3.5 m
  }}
  ego car on r lane -2 at 20 m speed 20 m/s {{
    stack bev perception {perception} cruise_speed 22 m/s
    {lidar}
  }}
{body}
}}"""


def spec_of(source: str):
    from addt_dsl.compiler import compile_source
    from addt_dsl.sweep import expand

    result = compile_source(source)
    assert result.plan is not None, [str(d) for d in result.diagnostics]
    return expand(result.plan).specs[0]


def rtf(n_agents: int, perception: str, duration: float, repeat: int) -> tuple[float, float, str]:
    """Best real-time factors over `repeat` runs: by the process's CPU time (what one core
    gives when nothing else runs) and by wall time; and the trace digest (equal across runs)."""
    from addt_dsl.runtime.execute import execute

    spec = spec_of(dense_source(n_agents, perception, duration))
    cpu_best, wall_best, digests = 0.0, 0.0, set()
    for _ in range(repeat):
        c0, w0 = time.process_time(), time.perf_counter()
        r = execute(spec, keep_trace=False)
        cpu, wall = time.process_time() - c0, time.perf_counter() - w0
        cpu_best, wall_best = max(cpu_best, r.sim_time_s / cpu), max(wall_best, r.sim_time_s / wall)
        digests.add(r.digest)
    assert len(digests) == 1, "a RunSpec gave two traces"
    return cpu_best, wall_best, digests.pop()


def profile(n_agents: int) -> None:
    import cProfile
    import pstats

    from addt_dsl.runtime.execute import execute

    spec = spec_of(dense_source(n_agents, "ground_truth", 5.0))
    execute(spec, keep_trace=False)
    pr = cProfile.Profile()
    pr.enable()
    execute(spec, keep_trace=False)
    pr.disable()
    pstats.Stats(pr).sort_stats("tottime").print_stats(25)


def main() -> None:
    try:
        import torch

        torch.set_num_threads(1)  # one core, as the target says
    except ImportError:
        pass
    if "--profile" in sys.argv:
        profile(int(sys.argv[sys.argv.index("--profile") + 1]))
        return
    load = os.getloadavg()
    print(f"dense traffic benchmark{' (quick)' if QUICK else ''}; load average {load[0]:.2f} {load[1]:.2f} "
          f"{load[2]:.2f} on {os.cpu_count()} cores (shared machine: figures are noisy)")
    counts = (1, 5, 20, 50) if QUICK else (1, 5, 20, 50, 100)
    duration, repeat = (4.0, 2) if QUICK else (10.0, 3)
    figures = {"quick": QUICK, "load_average": load, "duration_s": duration, "rtf": {}}
    print(f"  real-time factor, best of {repeat} runs of {duration:g} s: by CPU time (by wall time)")
    print(f"  {'agents':>6s}  {'ground truth':>18s}  {'learned':>18s}")
    for n in counts:
        row = {}
        for perception in ("ground_truth", "learned"):
            cpu, wall, _ = rtf(n, perception, duration, repeat)
            row[perception] = {"cpu": cpu, "wall": wall}
        figures["rtf"][n] = row
        print(f"  {n:6d}  " + "  ".join(f"{row[p]['cpu']:8.1f}x ({row[p]['wall']:5.1f}x)"
                                         for p in ("ground_truth", "learned")), flush=True)
    at50 = figures["rtf"][50]
    for perception, target in TARGET.items():
        cpu = at50[perception]["cpu"]
        print(f"  50 agents, {perception}: {cpu:.1f}x by CPU time = {cpu / target:.2f} of the {target:.0f}x target")
    figures_json.write(JSON_PATH, figures)


if __name__ == "__main__":
    main()
