"""Cost of the array step's leader lookup (`fleet.Views`: a view, then `leaders`) per
run-step, replayed from the calls of real runs: `bench_twin.traffic_source(N)` IDM
traffic (1 s) stepped in a batch of B runs with the agents as arrays, every view and
lookup call recorded, then replayed alone and timed (best of several repeats).

Run: PYTHONPATH=. python benchmarks/bench_views.py [--agents 5,20,50,100] [--batches 1,16,64]
     [--repeat 5] [--json FILE]
Prints, per configuration, us per run-step of the lookup (views + leaders, the Jacobi
and the sequential checks of the fixed point together; CPU time of the process and wall
time, each the least of the repeats: on a shared machine the CPU time is the steadier)
and a digest of every answer (two checkouts' digests must be equal), with the load
average beside.
"""

from __future__ import annotations

import hashlib
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import _figures as figures_json  # noqa: E402


def arg(name: str, default: str) -> list[int]:
    return [int(x) for x in (sys.argv[sys.argv.index(name) + 1] if name in sys.argv else default).split(",")]


def record(agents: int, batch: int) -> tuple[list, list, int]:
    """The Views' layouts and the (view, arguments) of every lookup of a batch's run, and
    the run-steps the batch took."""
    from bench_twin import compile_spec, traffic_source

    from addt_dsl.runtime import agents as agents_mod
    from addt_dsl.runtime import fleet
    from addt_dsl.runtime.execute import execute_batch

    agents_mod.ARRAY_MIN_AGENTS = agents_mod.STEP_MIN_AGENTS = 1
    spec = compile_spec(traffic_source(agents, sensors="", duration=1.0))
    specs = [spec.model_copy(update={"seed": spec.seed + i, "run_id": f"r{i:03d}"}) for i in range(batch)]
    layouts, calls = {}, []
    init, jacobi, sequential = fleet.Views.__init__, fleet.Views.jacobi, fleet.Views.sequential

    def rec_init(self, runs):
        init(self, runs)
        layouts[id(self)] = [tuple(np.copy(x) if isinstance(x, np.ndarray) else x for x in r) for r in runs]

    def rec_jacobi(self, s, t, v, ego):
        calls.append((id(self), "jacobi", tuple(np.copy(x) for x in (s, t, v)), tuple(np.copy(x) for x in ego)))
        return jacobi(self, s, t, v, ego)

    def rec_sequential(self, s, t, v, new, ego):
        calls.append((id(self), "sequential", tuple(np.copy(x) for x in (s, t, v)),
                      tuple(np.copy(x) for x in new), tuple(np.copy(x) for x in ego)))
        return sequential(self, s, t, v, new, ego)

    import numpy as np

    fleet.Views.__init__, fleet.Views.jacobi, fleet.Views.sequential = rec_init, rec_jacobi, rec_sequential
    try:
        results = execute_batch(specs, keep_trace=False)
    finally:
        fleet.Views.__init__, fleet.Views.jacobi, fleet.Views.sequential = init, jacobi, sequential
    steps = sum(round(r.sim_time_s / 0.01) for r in results)
    return layouts, calls, steps


def replay(layouts, calls, lengths) -> tuple[float, float, str]:
    """CPU and wall seconds to answer every recorded call once; a digest of the answers."""
    from addt_dsl.runtime import fleet

    views = {k: fleet.Views(runs) for k, runs in layouts.items()}
    h = hashlib.sha256()
    t0, c0 = time.perf_counter(), time.process_time()
    out = []
    for key, kind, (s, t, v), *rest in calls:
        w = views[key]
        view = w.jacobi(s, t, v, *rest) if kind == "jacobi" else w.sequential(s, t, v, *rest)
        out.append(w.leaders(view, s, t, lengths[key]))
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    for found, gap, speed in out:
        h.update(found.tobytes())
        h.update(gap.tobytes())
        h.update(speed[found].tobytes())
    return cpu, wall, h.hexdigest()[:16]


def main() -> None:
    import numpy as np

    repeat = arg("--repeat", "5")[0]
    figures: dict = {}
    print(f"load average before: {', '.join(f'{x:.2f}' for x in os.getloadavg())} on {os.cpu_count()} CPUs")
    print(f"{'agents':>6s} {'batch':>5s} {'calls':>6s} {'run-steps':>9s} {'cpu us/run-step':>15s} "
          f"{'wall':>7s}  digest")
    for agents in arg("--agents", "5,20,50,100"):
        for batch in arg("--batches", "1,16,64"):
            layouts, calls, steps = record(agents, batch)
            lengths = {k: np.concatenate([r[0] for r in runs]) for k, runs in layouts.items()}
            times = [replay(layouts, calls, lengths) for _ in range(repeat)]
            cpu, wall = min(c for c, _, _ in times), min(w for _, w, _ in times)
            load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
            print(f"{agents:6d} {batch:5d} {len(calls):6d} {steps:9d} {1e6 * cpu / steps:15.2f} "
                  f"{1e6 * wall / steps:7.2f}  {times[0][2]}  load {load}", flush=True)
            figures[f"{agents}x{batch}"] = {"cpu_us_per_run_step": 1e6 * cpu / steps,
                                            "wall_us_per_run_step": 1e6 * wall / steps, "digest": times[0][2]}
    figures_json.write(sys.argv[sys.argv.index("--json") + 1] if "--json" in sys.argv else None, figures)


if __name__ == "__main__":
    main()
