"""One meaning whatever the process: the same run keys give the same trace digests in
processes with different hash seeds (`PYTHONHASHSEED`), so nothing a run computes may
depend on set or dict order. Includes a junction with a vehicle light (OpenDRIVE type
1000001) and a pedestrian light (1000002) on one stop line, switched by two controllers."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.sim.conftest import EXAMPLES

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[3]

# fabriksgatan_traffic_lights.xodr, road 3 at s = 109 m: signal 1 (type 1000001, a vehicle
# light) and signal 3 (type 1000002, a pedestrian light), both facing +s traffic. The cars'
# light stays green; the walkers' turns red at 4 s, when the ego and the follower are still
# short of the line.
TWO_KINDS = """
scenario two_kinds {
  duration 12 s
  road town import "maps/fabriksgatan_traffic_lights.xodr" road 3
  lights {
    controller cars signals [1] green 60 s yellow 2 s red 30 s
    controller walkers signals [3] green 2 s yellow 2 s red 30 s
  }
  ego car on town route 3 -> straight -> 1 lane -1 at 55 m speed 8 m/s {
    stack bev cruise_speed 8 m/s
  }
  agent follower car on town route 3 -> straight -> 1 lane -1 at 30 m speed 8 m/s {
    behavior cruise speed 8 m/s
  }
  expect {
    no collision
    no red_light
    follower_goes: eventually travelled(follower) >= 70 m
  }
}
"""

# Each process compiles, runs and prints {run key: (digest, verdicts)} as JSON.
RUNNER = """
import json, sys
from pathlib import Path
from addt_dsl.compiler import compile_file, compile_source
from addt_dsl.runtime.execute import execute
from addt_dsl.sweep import expand
examples = Path(sys.argv[1])
out = {}
plans = [("two_kinds", compile_source(sys.argv[2], "two_kinds.addt", base_dir=examples).plan)]
plans += [(name, compile_file(examples / name).plan) for name in sys.argv[3:]]
for name, plan in plans:
    for i, spec in enumerate(expand(plan).specs[:2]):
        r = execute(spec)
        out[f"{name}#{i}"] = [r.trace.digest(), sorted((v.name, bool(v.passed)) for v in r.verdicts)]
print(json.dumps(out))
"""

RUN_FILES = ("red_light_runner.addt", "junction_cyclist.addt", "left_turn_yield.addt")


def _run(seed: int) -> dict:
    env = {**os.environ, "PYTHONHASHSEED": str(seed), "PYTHONPATH": str(ROOT)}
    done = subprocess.run([sys.executable, "-c", RUNNER, str(EXAMPLES), TWO_KINDS, *RUN_FILES],
                          env=env, cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_same_run_keys_same_digests_under_every_hash_seed():
    from concurrent.futures import ThreadPoolExecutor

    # Two processes at a time: each is single-threaded (one run after another).
    seeds = (0, 1, 2, 12345)
    with ThreadPoolExecutor(max_workers=2) as pool:
        runs = dict(zip(seeds, pool.map(_run, seeds)))
    first = runs[0]
    assert len(first) >= 4
    for seed, got in runs.items():
        assert got == first, f"PYTHONHASHSEED={seed} differs from 0"
    # The pedestrian light does not hold the cars: both drive through on their green.
    verdicts = dict(map(tuple, first["two_kinds#0"][1]))
    assert verdicts == {"no_collision": True, "no_red_light": True, "follower_goes": True}
