"""What following a route costs: real-time factors with and without routes.

Run: PYTHONPATH=. python benchmarks/bench_routes.py [--runs 5] [--json out.json]

Real-time factors are simulated seconds per CPU second of this process (`time.process_time`,
best of `--runs`: the machines are shared, and CPU time is what a run costs), ground-truth
perception:
- `overtake`: examples/overtake.addt, the reference run.
- `straight_road` / `straight_route`: one two-car scenario on straight_500m.xodr, without a
  route (the plain `FastRoad`) and with `route 1` on both cars (`RoutePath`): what the path
  machinery costs, `route_overhead` = 1 - rtf(route) / rtf(road).
- `route_cost_vs_overtake`: that extra CPU time per simulated second as a fraction of the
  overtake run's CPU time per simulated second, (1/rtf(route) - 1/rtf(road)) * rtf(overtake):
  how much slower the overtake run would be if its cars followed routes. The
  target: under 0.10.
- `junction_route`: the ego and a lead following `2 -> straight -> 0` through the junction
  of fabriksgatan.xodr (three roads and a connecting road), same stack and lidar as
  overtake.addt (a different scenario, for scale).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _figures as figures_json  # noqa: E402

from addt_dsl.compiler import compile_file, compile_source  # noqa: E402
from addt_dsl.runtime.execute import execute  # noqa: E402
from addt_dsl.sweep import expand  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
MAPS = ROOT / "examples"

STRAIGHT = """
scenario straight {{
  duration 20 s
  road r import "maps/straight_500m.xodr" road 1
  ego car on r {route}lane -1 at 20 m speed 20 m/s {{
    stack bev cruise_speed 25 m/s
    sensor lidar rate 10 Hz rays 360 range 80 m
  }}
  agent lead car on r {route}lane -1 at 70 m speed 12 m/s {{
    behavior cruise speed 12 m/s
  }}
}}
"""

JUNCTION = """
scenario junction {
  duration 20 s
  road town import "maps/fabriksgatan.xodr" road 2
  ego car on town route 2 -> straight lane -1 at 150 m speed 10 m/s {
    stack bev cruise_speed 10 m/s
    sensor lidar rate 10 Hz rays 360 range 80 m
  }
  agent lead car on town route 2 -> straight lane -1 at 200 m speed 8 m/s {
    behavior idm speed 9 m/s
  }
}
"""


def rtf(plan, runs: int) -> float:
    spec = expand(plan).specs[0]
    execute(spec, keep_trace=False)  # warm caches and imports
    best, digests = 0.0, set()
    for _ in range(runs):
        t0 = time.process_time()
        result = execute(spec, keep_trace=False)
        best = max(best, result.sim_time_s / (time.process_time() - t0))
        digests.add(result.digest)
    assert len(digests) == 1, "runs of one RunSpec differ"
    return best


def _plan(text: str):
    result = compile_source(text, "bench.addt", base_dir=MAPS)
    if result.plan is None:
        raise SystemExit("\n".join(str(d) for d in result.diagnostics))
    return result.plan


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--json", help="also write the figures here")
    args = ap.parse_args()
    figures = {
        "overtake": rtf(compile_file(ROOT / "examples" / "overtake.addt").plan, args.runs),
        "straight_road": rtf(_plan(STRAIGHT.format(route="")), args.runs),
        "straight_route": rtf(_plan(STRAIGHT.format(route="route 1 ")), args.runs),
        "junction_route": rtf(_plan(JUNCTION), args.runs),
    }
    figures["route_overhead"] = 1.0 - figures["straight_route"] / figures["straight_road"]
    figures["route_cost_vs_overtake"] = (1.0 / figures["straight_route"] - 1.0 / figures["straight_road"]) \
        * figures["overtake"]
    print(f"real-time factor (sim s per CPU s, best of {args.runs}): overtake.addt {figures['overtake']:.0f}x; "
          f"straight road {figures['straight_road']:.0f}x, same with `route 1` {figures['straight_route']:.0f}x "
          f"(path overhead {100 * figures['route_overhead']:.1f} %; as a share of the overtake run's cost "
          f"{100 * figures['route_cost_vs_overtake']:.1f} %, target < 10 %); through fabriksgatan's junction "
          f"{figures['junction_route']:.0f}x")
    figures_json.write(args.json, figures)


if __name__ == "__main__":
    main()
