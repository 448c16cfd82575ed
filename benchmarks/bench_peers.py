"""Side by side: the same car-following scenario in addt-dsl and in highway-env (rendering off).

Prints simulated seconds per wall second for each and their ratio. highway-env steps its
vehicles at `simulation_frequency` (15 Hz in highway-v0, 5 Hz in highway-fast-v0) with
kinematic bicycle models and no sensors; addt-dsl runs 100 Hz dynamics, a lidar by ray
casting and the full stack. The ratio is therefore a lower bound on what addt-dsl buys per
unit of fidelity. Needs `pip install highway-env` (a benchmark-only dependency).

    python benchmarks/bench_peers.py [--runs 5] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import time

FOLLOWING = """
scenario following {
  duration 30 s
  road r {
    line length 1500 m
    lanes right 2 width 3.5 m
  }
  ego car on r lane -2 at 20 m speed 25 m/s {
    stack bev cruise_speed 25 m/s
    sensor lidar rate 10 Hz rays 360 range 80 m
  }
  agent lead car on r lane -2 at 60 m speed 20 m/s {
    behavior cruise speed 20 m/s
  }
  expect {
    no collision
  }
}
"""


def addt_rtf(runs: int) -> float:
    from addt_dsl.compiler import compile_source
    from addt_dsl.runtime.execute import execute
    from addt_dsl.sweep import expand

    spec = expand(compile_source(FOLLOWING, "following.addt").plan).specs[0]
    execute(spec)  # warm-up: imports, first pybullet client
    t0 = time.perf_counter()
    sim = 0.0
    for _ in range(runs):
        sim += execute(spec, keep_trace=False).sim_time_s
    return sim / (time.perf_counter() - t0)


def highway_rtf(env_id: str, runs: int) -> float:
    import gymnasium as gym
    import highway_env  # noqa: F401 - registers the environments

    env = gym.make(env_id, config={"lanes_count": 2, "vehicles_count": 1, "duration": 30,
                                   "offscreen_rendering": True})
    env.reset(seed=0)
    cfg = env.unwrapped.config
    idle = 1  # DiscreteMetaAction: IDLE
    t0 = time.perf_counter()
    sim = 0.0
    for r in range(runs):
        env.reset(seed=r)
        done = truncated = False
        steps = 0
        while not (done or truncated):
            _, _, done, truncated, _ = env.step(idle)
            steps += 1
        sim += steps / cfg["policy_frequency"]
    return sim / (time.perf_counter() - t0)


def main(runs: int = 5) -> dict:
    figures = {"addt_dsl_rtf": addt_rtf(runs)}
    for env_id in ("highway-v0", "highway-fast-v0"):
        try:
            figures[f"{env_id}_rtf"] = highway_rtf(env_id, runs)
            figures[f"ratio_vs_{env_id}"] = figures["addt_dsl_rtf"] / figures[f"{env_id}_rtf"]
        except ImportError:
            figures[f"{env_id}_rtf"] = None
    return figures


if __name__ == "__main__":
    parser = argparse.ArgumentParser()
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--json")
    args = parser.parse_args()
    figures = main(args.runs)
    for k, v in figures.items():
        print(f"{k:28s} {v:10.1f}" if isinstance(v, float) else f"{k:28s} {v}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(figures, fh, indent=2)
