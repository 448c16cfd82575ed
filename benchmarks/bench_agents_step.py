"""Cost of the agents phase (`phases.agents`: the car-following step of every agent) per
run-step, in real runs: `bench_twin.traffic_source(N)` IDM traffic stepped in a batch of B
runs (`execute_batch`), the phase timed where the loop calls it (CPU time of the process
and wall time, each the least of the repeats: on a shared machine the CPU time is the
steadier), a digest of every run beside.

Run: PYTHONPATH=. python benchmarks/bench_agents_step.py [--agents 1,5,20,50,100]
     [--batches 1,16,64] [--repeat 3] [--duration 1.0] [--against OTHER_CHECKOUT] [--json FILE]
With `--against`, each configuration runs in a child process with this checkout and one
with the other (e.g. main's) back to back, and the table has both and their ratio
(other / this: > 1 is faster here); the digests must be equal.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import _figures as figures_json  # noqa: E402


def arg(name: str, default: str) -> str:
    return sys.argv[sys.argv.index(name) + 1] if name in sys.argv else default


def measure(agents: int, batch: int, repeat: int, duration: float) -> dict:
    """The least CPU and wall [us] of the agents phase per run-step over `repeat` batches."""
    import hashlib

    from bench_twin import compile_spec, traffic_source

    from addt_dsl.runtime import phases
    from addt_dsl.runtime.execute import execute_batch

    spec = compile_spec(traffic_source(agents, sensors="", duration=duration))
    specs = [spec.model_copy(update={"seed": spec.seed + i, "run_id": f"r{i:03d}"}) for i in range(batch)]
    step = phases.agents
    spent = [0.0, 0.0, 0]

    def timed(runs, ts, fleets):
        c0, t0 = time.process_time(), time.perf_counter()
        step(runs, ts, fleets)
        spent[0] += time.process_time() - c0
        spent[1] += time.perf_counter() - t0
        spent[2] += len(runs)

    phases.agents = timed
    try:
        execute_batch(specs[:1], keep_trace=False)  # warm: compiled kernels, caches
        best_cpu = best_wall = float("inf")
        digest = ""
        for _ in range(repeat):
            spent[:] = [0.0, 0.0, 0]
            results = execute_batch(specs, keep_trace=False)
            best_cpu, best_wall = min(best_cpu, spent[0] / spent[2]), min(best_wall, spent[1] / spent[2])
            digest = hashlib.sha256("".join(r.digest for r in results).encode()).hexdigest()[:16]
    finally:
        phases.agents = step
    return {"cpu_us": 1e6 * best_cpu, "wall_us": 1e6 * best_wall, "run_steps": spent[2], "digest": digest}


def child(root: str, agents: int, batch: int, repeat: int, duration: float) -> dict:
    env = {**os.environ, "PYTHONPATH": root}
    out = subprocess.run([sys.executable, str(HERE / "bench_agents_step.py"), "--child", str(agents), str(batch),
                          str(repeat), str(duration)], cwd=root, env=env, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    if "--child" in sys.argv:
        k = sys.argv.index("--child")
        agents, batch, repeat = (int(x) for x in sys.argv[k + 1:k + 4])
        print(json.dumps(measure(agents, batch, repeat, float(sys.argv[k + 4]))))
        return
    repeat, duration = int(arg("--repeat", "3")), float(arg("--duration", "1.0"))
    other = arg("--against", "")
    here = str(HERE.parent)
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    print(f"load average before: {load} on {os.cpu_count()} CPUs; agents phase, us per run-step (least of "
          f"{repeat}; cpu / wall)")
    head = f"{'agents':>6s} {'batch':>5s} {'this cpu':>9s} {'wall':>7s}"
    print(head + (f" {'other cpu':>9s} {'wall':>7s} {'ratio':>6s}  digests" if other else "  digest"))
    figures: dict = {}
    for agents in [int(x) for x in arg("--agents", "1,5,20,50,100").split(",")]:
        for batch in [int(x) for x in arg("--batches", "1,16,64").split(",")]:
            this = child(here, agents, batch, repeat, duration)
            row = f"{agents:6d} {batch:5d} {this['cpu_us']:9.2f} {this['wall_us']:7.2f}"
            fig = {"this": this}
            if other:
                that = child(other, agents, batch, repeat, duration)
                ratio = that["cpu_us"] / this["cpu_us"]
                same = "equal" if that["digest"] == this["digest"] else f"DIFFER {this['digest']} {that['digest']}"
                row += f" {that['cpu_us']:9.2f} {that['wall_us']:7.2f} {ratio:6.2f}  {same}"
                fig.update(other=that, ratio_cpu=ratio)
            else:
                row += f"  {this['digest']}"
            load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
            print(f"{row}  load {load}", flush=True)
            figures[f"{agents}x{batch}"] = fig
    figures_json.write(arg("--json", "") or None, figures)


if __name__ == "__main__":
    main()
