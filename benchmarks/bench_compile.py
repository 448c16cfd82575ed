"""Compile speed: `addtc check` over a suite of 1,000 generated scenario files, one core.

    python benchmarks/bench_compile.py [--files 1000] [--keep DIR]

Generates varied scenarios (every construct of the language appears across the suite,
sizes 1-4 kB), runs `addtc check` on all of them in one process pinned to one CPU, and
prints the wall time (target: well under 10 s), the per-file figure, and an in-process
split of parse vs checks. The grammar is built once per process and reused for every file.
"""

from __future__ import annotations

import argparse
import os
import random
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import _figures as figures_json  # benchmarks/ is on the path when run as a script

REPO = Path(__file__).resolve().parents[1]


def scenario(i: int, rng: random.Random) -> str:
    lanes = rng.randint(2, 4)
    n_agents = rng.randint(1, 6)
    parts = [f"# generated scenario {i}",
             f"scenario gen_{i} {{",
             f'  description "generated {i}"',
             f"  duration {rng.choice([10, 20, 30, 40])} s",
             f"  step {rng.choice([10, 20])} ms",
             f"  seed {i}",
             "  road main {",
             f"    line length {rng.randint(300, 800)} m",
             f"    arc length {rng.randint(50, 200)} m curvature {rng.choice([0.001, 0.002, -0.003])} /m",
             f"    spiral length 50 m from 0 /m to {rng.choice([0.001, -0.002])} /m",
             f"    line length {rng.randint(200, 500)} m",
             f"    lanes right {lanes} width {rng.choice([3.25, 3.5, 3.75])} m",
             "  }",
             f"  param lead_speed = 15 m/s in [8 m/s, {rng.randint(18, 25)} m/s]",
             f"  param gap = {rng.randint(20, 40)} m in [15 m, 60 m]",
             "  param drop_rate = 5 % in [0 %, 20 %]",
             f"  param react = 1 s in [0.5 s, 2 s] dist normal sd {rng.choice([0.2, 0.3])} s",
             "  assume headway: gap > lead_speed * 0.5 s",
             f"  ego car on main lane -1 at {rng.randint(10, 40)} m speed {rng.randint(15, 25)} m/s goal 550 m {{",
             f"    stack bev cruise_speed {rng.randint(20, 28)} m/s",
             f"    sensor lidar rate {rng.choice([10, 20])} Hz range {rng.choice([60, 80, 100])} m x 1.5 m z 1.8 m",
             "  }",
             "  agent lead car ahead of ego gap speed lead_speed {",
             "    behavior cruise speed lead_speed",
             "    sequence {",
             "      when gap(ego, lead) < 30 m then behavior brake decel 4 m/s^2",
             "      after react behavior cruise speed lead_speed",
             "    }",
             "  }"]
    for k in range(n_agents - 1):
        lane = -rng.randint(1, lanes)
        kind = rng.choice(["car", "car", "truck", "cyclist"])
        parts += [f"  agent a{k} {kind} on main lane {lane} at {rng.randint(60, 300)} m speed {rng.randint(5, 20)} m/s {{",
                  f"    behavior idm speed {rng.randint(10, 25)} m/s time_gap {rng.choice([1, 1.5, 2])} s",
                  f"    at {rng.randint(2, 8)} s behavior lane_change to {lane} duration 3 s",
                  "  }"]
    parts += ["  faults {",
              "    drop lidar rate drop_rate",
              f"    at {rng.randint(2, 6)} s for 2 s delay lidar by {rng.choice([50, 100, 200])} ms",
              f"    during [{rng.randint(1, 4)} s, {rng.randint(5, 9)} s] bitflip control.steer count 2",
              "  }",
              "  expect {",
              "    no collision",
              "    stay in lane tolerance 1 m",
              "    min ttc to lead 1.5 s",
              "    warn max jerk 10 m/s^3",
              "    max latency 150 ms",
              "    headway_kept: always gap(ego, lead) > 2 m",
              "    eventually within 8 s speed(ego) > 5 m/s",
              "  }",
              "  sweep {",
              f"    grid drop_rate in [0, {rng.randint(2, 10)}, 15] %",
              f"    {rng.choice(['random', 'halton', 'lhs'])} {rng.randint(2, 8)} seed {i}",
              f"    repeat {rng.randint(1, 3)}",
              "  }",
              "}"]
    return "\n".join(parts) + "\n"


def generate(directory: Path, count: int) -> list[Path]:
    rng = random.Random(20240611)
    paths = []
    for i in range(count):
        p = directory / f"gen_{i:04d}.addt"
        p.write_text(scenario(i, rng))
        paths.append(p)
    return paths


def _one_core_prefix() -> list[str]:
    return ["taskset", "-c", "0"] if shutil.which("taskset") else []


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--files", type=int, default=1000)
    ap.add_argument("--keep", help="write the suite here instead of a temp dir")
    ap.add_argument("--json", help="also write the figures here")
    args = ap.parse_args()
    tmp = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="addt-bench-"))
    tmp.mkdir(parents=True, exist_ok=True)
    paths = generate(tmp, args.files)
    size_kb = sum(p.stat().st_size for p in paths) / 1024
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    cmd = [*_one_core_prefix(), sys.executable, "-m", "addt_dsl.cli", "check", *map(str, paths)]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, cwd=tmp)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    failed = proc.returncode != 0
    startup_cmd = [*_one_core_prefix(), sys.executable, "-c", "import addt_dsl.cli, addt_dsl.compiler"]
    t0 = time.perf_counter()
    subprocess.run(startup_cmd, env=env, check=True)
    startup = time.perf_counter() - t0

    # In-process split (same process, grammar already built by the first file).
    sys.path.insert(0, str(REPO))
    from addt_dsl.compiler import compile_file
    from addt_dsl.compiler import parser as P
    from addt_dsl.diagnostics import DiagnosticSink

    compile_file(paths[0])
    texts = [p.read_bytes() for p in paths]
    t0 = time.perf_counter()
    for p, text in zip(paths, texts):
        P.parse_source(text, str(p), DiagnosticSink())
    parse_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    chunk_cpu = []
    for k in range(0, len(paths), 50):
        c0 = time.process_time()
        for p in paths[k:k + 50]:
            compile_file(p)
        chunk_cpu.append((time.process_time() - c0) / len(paths[k:k + 50]))
    compile_s = time.perf_counter() - t0

    print(f"suite: {len(paths)} files, {size_kb:.0f} kB in {tmp}")
    print(f"addtc check, one process on one core{' (taskset -c 0)' if _one_core_prefix() else ''}: "
          f"{wall:.2f} s wall, {cpu:.2f} s CPU ({1000 * cpu / len(paths):.2f} ms CPU/file) "
          f"exit={proc.returncode}")
    print(f"  load average during the run: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores "
          "(wall time inflates on a busy machine; CPU time much less)")
    print(f"  of which interpreter start + imports: {startup:.2f} s")
    print(f"in-process: compile {1000 * compile_s / len(paths):.2f} ms/file, "
          f"parse only {1000 * parse_s / len(paths):.2f} ms/file "
          f"({100 * parse_s / compile_s:.0f} % of compile)")
    best = min(chunk_cpu)
    print(f"  fastest 50-file chunk: {1000 * best:.2f} ms CPU/file -> {best * len(paths) + startup:.2f} s for the "
          "suite on an idle core (estimate: other processes slow a busy machine's every chunk)")
    print(f"target ratio: {wall / 10.0:.2f} (wall) / {cpu / 10.0:.2f} (CPU) of the 10 s budget")
    figures_json.write(args.json, {
        "files": len(paths), "wall_s": wall, "cpu_s": cpu, "cpu_ms_per_file": 1000 * cpu / len(paths),
        "startup_s": startup, "parse_share": parse_s / compile_s,
        "idle_core_estimate_s": best * len(paths) + startup,
        "target_s": 10.0, "ratio_wall_to_target": wall / 10.0, "ratio_cpu_to_target": cpu / 10.0,
        "exit_code": proc.returncode})
    if failed:
        print(proc.stderr[-2000:], file=sys.stderr)
    if not args.keep:
        shutil.rmtree(tmp, ignore_errors=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
