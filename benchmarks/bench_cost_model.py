"""Measure the wall-time coefficients of the cost model (addt_dsl/cost.py, `WALL_*`).

Run: PYTHONPATH=. python benchmarks/bench_cost_model.py [--quick] [--json FILE]

Each probe is one closed-loop run in this process (the best of a few, the machine being
shared), with the `bev` stack and ground-truth perception; the coefficients follow from
differences between probes:

    wall per run = run overhead + steps x (per step + per actor x actors)
                   + lidar rays x per ray + camera pixels x per pixel

Printed: every probe's wall time, the fitted coefficients, and each probe's estimate
from them (within 25 % of the measurement is the model's claim; docs/limits.md).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import _figures as figures_json

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
QUICK = "--quick" in sys.argv
JSON_PATH = sys.argv[sys.argv.index("--json") + 1] if "--json" in sys.argv else None

TEMPLATE = """scenario probe {{
  duration {duration} s
  step 10 ms
  road r {{
    line length 3000 m
    lanes right 3 width 3.5 m
  }}
  ego car on r lane -2 at 20 m speed 10 m/s {{
    stack bev cruise_speed 10 m/s
    sensor lidar rate {rate} Hz rays {rays} range 60 m
    {camera}
  }}
{agents}
  expect {{
    no collision
  }}
}}
"""


def probe(duration: float = 10.0, agents: int = 0, rays: int = 360, rate: float = 10.0, camera: str = ""):
    from addt_dsl import cost
    from addt_dsl.compiler import compile_source
    from addt_dsl.runtime.execute import execute
    from addt_dsl.sweep import expand

    lines = "\n".join(f"  agent a{i} car on r lane {-1 - i % 3} at {60 + 25 * (i // 3)} m speed 10 m/s"
                      for i in range(agents))
    source = TEMPLATE.format(duration=duration, rays=rays, rate=rate, camera=camera, agents=lines)
    result = compile_source(source, path="probe.addt")
    assert result.ok, result.diagnostics
    (spec,) = expand(result.plan).specs
    best = float("inf")
    for _ in range(1 if QUICK else 3):
        t0 = time.perf_counter()
        execute(spec, keep_trace=False)
        best = min(best, time.perf_counter() - t0)
    return best, cost.estimate(result.plan)


def main() -> None:
    from addt_dsl.cost import wall_seconds_per_run

    d = 3.0 if QUICK else 10.0
    probes = {
        "short": probe(duration=1.0),
        "base": probe(duration=d),
        "agents_20": probe(duration=d, agents=20),
        "rays_x10": probe(duration=d, rays=3600),
        "camera_320x240": probe(duration=d, camera="sensor camera width 320 height 240 rate 10 Hz"),
    }
    (t1, e1), (t0, e0) = probes["short"], probes["base"]
    per_step = (t0 - t1) / (e0.samples_per_run - e1.samples_per_run)
    overhead = t1 - per_step * e1.samples_per_run
    ta, ea = probes["agents_20"]
    per_actor_step = (ta - t0) / (ea.agent_steps_per_run - e0.agent_steps_per_run)
    tr, er = probes["rays_x10"]
    per_ray = (tr - t0) / (er.lidar_rays_per_run - e0.lidar_rays_per_run)
    tc, ec = probes["camera_320x240"]
    per_pixel = (tc - t0) / ec.camera_pixels_per_run
    fitted = {"run_overhead_s": overhead, "per_step_s": per_step - per_actor_step,
              "per_actor_step_s": per_actor_step, "per_lidar_ray_s": per_ray, "per_camera_pixel_s": per_pixel}
    out = {"probes": {}, "fitted": fitted}
    for name, (t, e) in probes.items():
        model = wall_seconds_per_run(e)
        out["probes"][name] = {"wall_s": round(t, 4), "model_s": round(model, 4), "ratio": round(model / t, 3)}
        print(f"{name:16s} measured {t:8.3f} s   model (addt_dsl/cost.py) {model:8.3f} s   x{model / t:.2f}")
    print("fitted from these probes:", {k: f"{v:.3g}" for k, v in fitted.items()})
    figures_json.write(JSON_PATH, out)


if __name__ == "__main__":
    main()
