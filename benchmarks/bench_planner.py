"""Per-call cost of the bev stack's lattice planner (`LatticePlanner.plan`) and controller
(`Controller.command`) at 0/5/20/50 objects, this checkout against another (a baseline).

    PYTHONPATH=. python benchmarks/bench_planner.py [--base DIR] [--repeats N]

Each checkout is measured in its own child process (`PYTHONPATH` set to it), the two
alternating `--rounds` times so a burst of load on a shared host falls on both; per case
the least time per call over all rounds (us), with the ratio base / this and the load
average. Objects are cars on a straight 2-lane road within 60 m of the ego, some braking
(the tuples the stack passes: s, t, v_s, v_t, length, width, a_s, a_t). Without `--base`
only this checkout is measured.
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
COUNTS = (0, 5, 20, 50)


def child(repeats: int) -> dict:
    import numpy as np

    from addt_dsl.stack.calibrate import _road
    from addt_dsl.stack.control import Controller
    from addt_dsl.stack.nodes import LatticePlanner, Plan
    from addt_dsl.vehicles import CAR, DEFAULT_WHEELBASE_M

    road = _road()
    lanes = road.driving_lane_ids(100.0)
    lane0 = lanes[0]
    t0 = float(road.lane_center_t(lane0, 100.0))
    ident = lambda site, v: v  # noqa: E731
    cases = {}
    for n in COUNTS:
        rng = np.random.default_rng(n)
        objs = [(100.0 + float(rng.uniform(-60, 60)), float(road.lane_center_t(int(rng.choice(lanes)), 100.0)),
                 float(rng.uniform(10, 30)), 0.0, CAR.length_m, CAR.width_m,
                 float(rng.choice([0.0, -3.0])), 0.0) for _ in range(n)]
        cases[f"plan {n:2d} objects"] = (lambda objs=objs: LatticePlanner({}).plan(
            (100.0, t0, lane0), 25.0, objs, road, "r", 0.0, ident), repeats)
    ctl = Controller({}, DEFAULT_WHEELBASE_M)
    t_lane = float(road.lane_center_t(-1, 100.0))
    plan = Plan(-1, t_lane + 1.0, 25.0, 90.0, t_lane, 60.0, 0.0)
    x, y, h = road.reference_pose(100.0)
    cases["command"] = (lambda: ctl.command(plan, (x, y, h, 24.0), road, 100.0, t_lane, 0.01, ident), repeats * 10)
    for fn, _ in cases.values():  # first calls (compiles, caches) untimed
        fn()
    out = {}
    for _ in range(5):  # the least of 5 batches per case, interleaved
        for name, (fn, number) in cases.items():
            t = time.perf_counter()
            for _ in range(number):
                fn()
            us = (time.perf_counter() - t) / number * 1e6
            out[name] = min(us, out.get(name, us))
    return out


def run_in(root: Path, repeats: int) -> dict:
    env = dict(os.environ, PYTHONPATH=str(root), OMP_NUM_THREADS="1")
    res = subprocess.run([sys.executable, __file__, "--child", str(repeats)], env=env, cwd=root,
                         capture_output=True, text=True, check=True)
    return json.loads(res.stdout.strip().splitlines()[-1])


def main() -> None:
    if "--child" in sys.argv:
        print(json.dumps(child(int(sys.argv[sys.argv.index("--child") + 1]))))
        return
    repeats = int(sys.argv[sys.argv.index("--repeats") + 1]) if "--repeats" in sys.argv else 200
    rounds = int(sys.argv[sys.argv.index("--rounds") + 1]) if "--rounds" in sys.argv else 3
    base = Path(sys.argv[sys.argv.index("--base") + 1]) if "--base" in sys.argv else None
    load = lambda: ", ".join(f"{x:.2f}" for x in os.getloadavg())  # noqa: E731
    print(f"load before: {load()}")
    best: dict[str, dict[str, float]] = {"base": {}, "this": {}}
    for _ in range(rounds):
        for name, root in (("base", base), ("this", ROOT)):
            if root is None:
                continue
            for k, v in run_in(root, repeats).items():
                best[name][k] = min(v, best[name].get(k, v))
    print(f"{'us per call':20s} {'base':>9s} {'this':>9s} {'base/this':>9s}")
    for k, v in best["this"].items():
        b = best["base"].get(k)
        print(f"{k:20s} {b if b is not None else float('nan'):9.1f} {v:9.1f} "
              f"{b / v if b is not None else float('nan'):8.2f}x")
    print(f"load after: {load()}")
    figures_json.write(sys.argv[sys.argv.index("--json") + 1] if "--json" in sys.argv else None,
                       {"us_per_call": best})


if __name__ == "__main__":
    main()
