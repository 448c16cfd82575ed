"""The cost check includes a wall-time estimate from the measured model (addt_dsl/cost.py)
and refuses a sweep or a run beyond the documented thresholds unless `--allow-large`: a sweep
at exactly the other default limits (10^6 runs x 10 s) started and reported "about 95 h
left"; a 10^9-pixel camera run was accepted, then killed by its time bound."""

from __future__ import annotations

from addt_dsl import cost
from addt_dsl.cli import main as addtc
from addt_dsl.compiler import compile_source
from addt_dsl.limits import DEFAULT
from addt_dsl.runtime.executor import run_time_bound_s
from addt_dsl.sweep import expand

SWEEP = """scenario big_sweep {{
  duration 10 s
  road r {{
    line length 300 m
  }}
  param gap = 20 m in [10 m, 40 m]
  ego car on r lane -1 at 10 m speed 10 m/s {{
    {sensor}
  }}
  agent lead car on r lane -1 at 30 m + gap speed 10 m/s
  expect {{
    no collision
  }}
  sweep {{
    random {runs}
  }}
}}
"""


def _errors(result):
    return [(d.code, d.message) for d in result.diagnostics if d.is_error]


def test_a_million_ten_second_runs_are_refused_for_their_wall_time(tmp_path):
    source = SWEEP.format(runs=1_000_000, sensor="sensor lidar")
    ((code, message),) = _errors(compile_source(source, path="big.addt"))
    assert code == "E0701" and "wall_seconds" in message
    assert compile_source(source, path="big.addt", limits=DEFAULT.raised(allow_large=True)).ok
    small = compile_source(SWEEP.format(runs=100, sensor="sensor lidar"), path="small.addt")
    assert small.ok and any("wall time: about" in line for line in small.estimate.lines())
    path = tmp_path / "big.addt"
    path.write_text(source)
    assert addtc(["check", str(path)]) == 2
    assert addtc(["check", str(path), "--allow-large"]) == 0


def test_the_estimate_follows_the_measured_coefficients():
    plan = compile_source(SWEEP.format(runs=10, sensor="sensor lidar"), path="s.addt").plan
    est = cost.estimate(plan)
    by_hand = (cost.WALL_RUN_S + 1001 * cost.WALL_STEP_S + 1001 * 2 * cost.WALL_ACTOR_STEP_S
               + 360 * 10 * 10 * cost.WALL_LIDAR_RAY_S)  # 360 rays, 1 channel, 10 Hz, 10 s (the defaults)
    assert est.lidar_rays_per_run == 36_000 and abs(est.run_wall_s - by_hand) < 1e-12
    assert abs(est.wall_s - 10 * by_hand) < 1e-9


def test_a_huge_camera_run_is_refused_or_given_time_enough():
    camera = "sensor camera width 1920 height 1080 rate 60 Hz"  # 1.2e9 pixels in 10 s
    (code, message), *_ = _errors(compile_source(SWEEP.format(runs=1, sensor=camera), path="c.addt"))
    assert code == "E0701"
    # Within the pixel threshold (1e9) but slow: accepted, and its default bound covers it.
    camera = "sensor camera width 1920 height 1000 rate 50 Hz"  # 9.6e8 pixels, about 450 s
    result = compile_source(SWEEP.format(runs=1, sensor=camera), path="c.addt")
    assert result.ok, _errors(result)
    (spec,) = expand(result.plan).specs[:1]
    assert result.estimate.run_wall_s > 300
    assert run_time_bound_s(spec) >= 10 * result.estimate.run_wall_s > 60 + 10 / 0.1
