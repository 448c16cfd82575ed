"""Cost of the agents' pose phase (`agents.Fleets.pose`: every agent's road point, lane
offset, ground scale, elevation, body heading and pitch, handed to physics) per run-step,
and of `FastRoad.project` per call, in two checkouts back to back.

Each configuration runs `bench_twin.traffic_source(N)` IDM traffic (1 s, no sensors) in a
batch of B runs in a child process per checkout (its PYTHONPATH the checkout), alternating
checkouts, with the pose phase timed inside the loop (the least of the repeats), and the
`project` calls of the run (the ego's projection onto its road) recorded and replayed alone.
`--pose-min K` sets `agents.ARRAY_MIN_AGENTS` (posing as arrays from K agents in a batch; by
default each checkout's own) in both. By default the one checkout `.`; before/after:
`--checkouts /path/to/main,.`.

Run: PYTHONPATH=. python benchmarks/bench_pose.py [--checkouts A,B] [--agents 1,5,20,50,100]
     [--batches 1,16,64] [--repeat 3] [--pose-min K] [--json FILE]
Prints per configuration and checkout the CPU us per run-step of the pose phase (process
time; wall beside), us per `project` call, the ratio first/last checkout, and the load.
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


def arg(name: str, default: str) -> str:
    return sys.argv[sys.argv.index(name) + 1] if name in sys.argv else default


def child(agents: int, batch: int, repeat: int, pose_min: int | None) -> dict:
    """In a checkout: the pose phase's least CPU and wall seconds per run-step, us per
    `project` call (replayed), and the configuration's digest."""
    import hashlib

    from bench_twin import compile_spec, traffic_source

    from addt_dsl.runtime import agents as A
    from addt_dsl.runtime.execute import execute_batch
    from addt_dsl.runtime.fastroad import FastRoad

    if pose_min is not None:
        A.ARRAY_MIN_AGENTS = pose_min
    spec = compile_spec(traffic_source(agents, sensors="", duration=1.0))
    specs = [spec.model_copy(update={"seed": spec.seed + i, "run_id": f"r{i:03d}"}) for i in range(batch)]
    pose, project = A.Fleets.pose, FastRoad.project
    spent = [0.0, 0.0]
    calls: list = []

    def timed(self, runs, ts):
        c0, t0 = time.process_time(), time.perf_counter()
        pose(self, runs, ts)
        spent[0] += time.process_time() - c0
        spent[1] += time.perf_counter() - t0

    def recorded(self, x, y, hint=None):
        calls.append((self, x, y, hint))
        return project(self, x, y, hint)

    execute_batch(specs[:1], keep_trace=False)  # (compiles the kernels, if any)
    A.Fleets.pose, FastRoad.project = timed, recorded
    best = None
    digest = hashlib.sha256()
    try:
        for k in range(repeat):
            spent[:] = [0.0, 0.0]
            calls.clear()
            results = execute_batch(specs, keep_trace=False)
            steps = sum(round(r.sim_time_s / 0.01) for r in results)
            per = (spent[0] / steps, spent[1] / steps)
            best = per if best is None else (min(best[0], per[0]), min(best[1], per[1]))
            if k == 0:
                for r in results:
                    digest.update(r.digest.encode())
    finally:
        A.Fleets.pose, FastRoad.project = pose, project
    replay = calls * max(1, 20000 // max(1, len(calls)))
    per_call = []
    for _ in range(5):
        t0 = time.process_time()
        for road, x, y, hint in replay:
            project(road, x, y, hint)
        per_call.append((time.process_time() - t0) / len(replay))
    return {"pose_cpu_us": 1e6 * best[0], "pose_wall_us": 1e6 * best[1], "project_us": 1e6 * min(per_call),
            "project_calls_per_run_step": len(calls) / steps, "digest": digest.hexdigest()[:16]}


def main() -> None:
    if "--child" in sys.argv:
        agents, batch, repeat = (int(x) for x in arg("--child", "").split(","))
        pose_min = int(arg("--pose-min", "-1"))
        print(json.dumps(child(agents, batch, repeat, None if pose_min < 0 else pose_min)))
        return
    checkouts = [str(Path(p).resolve()) for p in arg("--checkouts", ".").split(",")]
    repeat = int(arg("--repeat", "3"))
    extra = ["--pose-min", arg("--pose-min", "")] if "--pose-min" in sys.argv else []
    figures: dict = {"checkouts": checkouts}
    print(f"load average before: {', '.join(f'{x:.2f}' for x in os.getloadavg())} on {os.cpu_count()} CPUs")
    print("checkouts: " + "  ".join(f"[{i}] {c}" for i, c in enumerate(checkouts)))
    print(f"{'agents':>6s} {'batch':>5s} {'ck':>3s} {'pose cpu us/run-step':>20s} {'wall':>8s} "
          f"{'project us':>10s} {'calls/step':>10s}  digest")
    for agents in (int(x) for x in arg("--agents", "1,5,20,50,100").split(",")):
        for batch in (int(x) for x in arg("--batches", "1,16,64").split(",")):
            rows = []
            for i, checkout in enumerate(checkouts):
                env = {**os.environ, "PYTHONPATH": checkout}
                out = subprocess.run([sys.executable, __file__, "--child", f"{agents},{batch},{repeat}", *extra],
                                     env=env, capture_output=True, text=True, check=True).stdout
                row = json.loads(out.strip().splitlines()[-1])
                rows.append(row)
                print(f"{agents:6d} {batch:5d} {i:3d} {row['pose_cpu_us']:20.2f} {row['pose_wall_us']:8.2f} "
                      f"{row['project_us']:10.3f} {row['project_calls_per_run_step']:10.2f}  {row['digest']}",
                      flush=True)
            load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
            first, last = rows[0], rows[-1]
            print(f"{'':6s} {'':5s} ratio [0]/[{len(rows) - 1}]: pose {first['pose_cpu_us'] / last['pose_cpu_us']:.2f}x"
                  f"  project {first['project_us'] / last['project_us']:.2f}x"
                  f"  digests {'equal' if len({r['digest'] for r in rows}) == 1 else 'DIFFER'}  load {load}",
                  flush=True)
            figures[f"{agents}x{batch}"] = rows
    figures_json.write(arg("--json", "") or None, figures)


if __name__ == "__main__":
    main()
