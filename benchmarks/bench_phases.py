"""Per-phase cost of the engine's step (`batch._loop`, `phases.py`) per run-step, in two
checkouts back to back, with perf_counter (cProfile inflates code of many small calls).

Each configuration runs `bench_dense.dense_source(N)` (IDM traffic, the ground-truth bev
stack with its lidar; 1 s) in a batch of B runs, in a child process per checkout (its
PYTHONPATH the checkout), alternating checkouts, `--repeat` times; each phase function of
`phases` (the loop calls them by module attribute) is wrapped by a timer. `loop` is the
loop's own body: the loop's time less the phases' (the timers' own ~0.1 us a call land
there too, the same in both checkouts). The least of the repeats per phase.

Run: PYTHONPATH=. python benchmarks/bench_phases.py [--checkouts OTHER_CHECKOUT,.] [--agents 1,5,20,50,100]
     [--batches 1,16] [--repeat 3] [--phases pose,record,...] [--json FILE]
Prints us per run-step per phase and checkout, the ratio first/last, and the load.
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

PHASES = ("clock", "pose", "record", "collisions", "environment", "variables", "lights", "outputs", "end",
          "triggers", "sense", "stack", "ego", "agents")
SHOWN = ("pose", "record", "collisions", "ego", "agents", "loop", "total")


def arg(name: str, default: str) -> str:
    return sys.argv[sys.argv.index(name) + 1] if name in sys.argv else default


def child(agents: int, batch: int, repeat: int) -> dict:
    """In a checkout: least us per run-step of each phase, the loop's own body, the loop."""
    import hashlib

    from bench_dense import dense_source, spec_of

    from addt_dsl.runtime import batch as B
    from addt_dsl.runtime import phases
    from addt_dsl.runtime.execute import execute_batch

    spec = spec_of(dense_source(agents, "ground_truth", 1.0))
    specs = [spec.model_copy(update={"seed": spec.seed + i, "run_id": f"r{i:03d}"}) for i in range(batch)]
    execute_batch(specs[:1], keep_trace=False)  # (compiles the kernels)
    spent = dict.fromkeys(PHASES, 0.0)
    spent["total"] = 0.0
    clock = time.perf_counter
    originals = {name: getattr(phases, name) for name in PHASES}
    loop = B._loop

    def wrap(name, fn):
        def timed(*args):
            t0 = clock()
            out = fn(*args)
            spent[name] += clock() - t0
            return out
        return timed

    def timed_loop(runs):
        t0 = clock()
        out = loop(runs)
        spent["total"] += clock() - t0
        return out

    best: dict = {}
    digest = hashlib.sha256()
    for name, fn in originals.items():
        setattr(phases, name, wrap(name, fn))
    B._loop = timed_loop
    try:
        for k in range(repeat):
            for key in spent:
                spent[key] = 0.0
            results = execute_batch(specs, keep_trace=False)
            steps = sum(round(r.sim_time_s / 0.01) for r in results)
            per = {key: 1e6 * v / steps for key, v in spent.items()}
            per["loop"] = per["total"] - sum(per[p] for p in PHASES)
            best = per if not best else {key: min(best[key], v) for key, v in per.items()}
            if k == 0:
                for r in results:
                    digest.update(r.digest.encode())
    finally:
        for name, fn in originals.items():
            setattr(phases, name, fn)
        B._loop = loop
    best["digest"] = digest.hexdigest()[:16]
    return best


def main() -> None:
    if "--child" in sys.argv:
        agents, batch, repeat = (int(x) for x in arg("--child", "").split(","))
        print(json.dumps(child(agents, batch, repeat)))
        return
    checkouts = [str(Path(p).resolve()) for p in arg("--checkouts", ".").split(",")]
    repeat = int(arg("--repeat", "3"))
    shown = tuple(arg("--phases", ",".join(SHOWN)).split(","))
    figures: dict = {"checkouts": checkouts}
    print(f"load average before: {', '.join(f'{x:.2f}' for x in os.getloadavg())} on {os.cpu_count()} CPUs")
    print("checkouts: " + "  ".join(f"[{i}] {c}" for i, c in enumerate(checkouts)))
    print("us per run-step (perf_counter, least of repeats)")
    print(f"{'agents':>6s} {'batch':>5s} {'ck':>3s} " + " ".join(f"{p:>10s}" for p in shown) + "  digest")
    for agents in (int(x) for x in arg("--agents", "1,5,20,50,100").split(",")):
        for batch in (int(x) for x in arg("--batches", "1,16").split(",")):
            rows = []
            for i, checkout in enumerate(checkouts):
                env = {**os.environ, "PYTHONPATH": checkout}
                out = subprocess.run([sys.executable, __file__, "--child", f"{agents},{batch},{repeat}"],
                                     env=env, capture_output=True, text=True, check=True).stdout
                row = json.loads(out.strip().splitlines()[-1])
                rows.append(row)
                print(f"{agents:6d} {batch:5d} {i:3d} " + " ".join(f"{row[p]:10.2f}" for p in shown)
                      + f"  {row['digest']}", flush=True)
            first, last = rows[0], rows[-1]
            load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
            print(f"{'':6s} {'':5s} {'[0]/[-1]':>3s} " + " ".join(
                f"{first[p] / last[p]:9.2f}x" if last[p] > 0 else f"{'-':>10s}" for p in shown)
                + f"  digests {'equal' if len({r['digest'] for r in rows}) == 1 else 'DIFFER'}  load {load}",
                flush=True)
            figures[f"{agents}x{batch}"] = rows
    figures_json.write(arg("--json", "") or None, figures)


if __name__ == "__main__":
    main()
