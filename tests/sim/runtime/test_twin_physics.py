"""The twin in the loop: lane change at 30 m/s through the stack, friction from the DSL,
elevated roads, and camera/IMU/GNSS runs that stay deterministic."""

import math
from pathlib import Path

import numpy as np
import pytest

from addt_dsl.compiler import compile_source
from addt_dsl.runtime import batch
from addt_dsl.runtime import execute as X
from addt_dsl.runtime.state import RunState
from addt_dsl.sweep import expand

pytestmark = pytest.mark.slow
XODR = Path(__file__).resolve().parents[2] / "data" / "xodr"


def spec_of(source: str, base_dir="."):
    result = compile_source(source, base_dir=base_dir)
    assert result.plan is not None, [str(d) for d in result.diagnostics]
    return expand(result.plan).specs[0]


LANE_CHANGE = """
scenario lane_change_30 {{
  duration 10 s
  road r {{
    line length 800 m
    lanes right 2 width 3.5 m
  }}
  ego car on r lane {lane} at 20 m speed 30 m/s {{
    stack bev cruise_speed 30 m/s lane_policy keep_right
    sensor lidar rate 10 Hz rays 720 range 100 m
  }}
{agents}
}}"""


def swings(err: np.ndarray, amplitude: float = 0.05) -> int:
    """Excursions of `err` to either side of zero larger than `amplitude`, after the
    approach (the first crossing): 1 = an overshoot, 2 = overshoot and one correction."""
    parts = np.split(err, np.where(np.diff(np.sign(err)) != 0)[0] + 1)[1:]
    return sum(1 for part in parts if np.abs(part).max() > amplitude)


def test_stack_lane_change_at_30_mps_settles_without_overshoot():
    # An empty road: the planner's keep-right policy moves the ego over at full speed.
    out = X.execute(spec_of(LANE_CHANGE.format(lane=-1, agents="")))
    assert out.status == "ok"
    ego = out.trace.actors["ego"]
    target = -5.25
    assert ego.speed.min() > 29.0
    assert ego.t.min() >= target - 0.3  # overshoot past the target lane centre
    arrived = int(np.argmax(ego.t < target + 0.3))
    assert arrived * out.trace.period_s < 4.0
    assert np.abs(ego.t[arrived:] - target).max() <= 0.3
    assert np.abs(ego.t[-200:] - target).max() < 0.05  # settled
    assert swings(ego.t[arrived:] - target) <= 2  # no oscillation


def test_stack_overtaking_lane_change_behind_a_slower_car():
    out = X.execute(spec_of(LANE_CHANGE.format(lane=-2, agents="""
  agent slow car on r lane -2 at 60 m speed 25 m/s {
    behavior cruise speed 25 m/s
  }""")))
    assert out.status == "ok" and not out.trace.events_of("collision")
    ego = out.trace.actors["ego"]
    target = -1.75
    assert ego.t.max() <= target + 0.3
    arrived = int(np.argmax(ego.t > target - 0.3))
    assert 0 < arrived and np.abs(ego.t[arrived:] - target).max() <= 0.3
    assert abs(ego.t[-1] - target) < 0.05
    assert swings(ego.t[arrived:] - target) <= 2


def friction_scenario(mu: float) -> str:
    return f"""
scenario brake_{int(mu * 10)} {{
  duration 8 s
  road r {{
    line length 400 m
    lanes right 1 width 3.5 m
  }}
  ego car on r lane -1 at 10 m speed 25 m/s mu {mu} {{
    stack bev cruise_speed 25 m/s
    sensor lidar rate 10 Hz rays 720 range 100 m
  }}
  agent stopped car on r lane -1 at 120 m speed 0 m/s {{
    behavior cruise speed 0 m/s
  }}
}}"""


def test_friction_from_the_dsl_changes_the_stop():
    dry = X.execute(spec_of(friction_scenario(0.9))).trace
    icy = X.execute(spec_of(friction_scenario(0.2))).trace
    assert not dry.events_of("collision")
    assert icy.events_of("collision")  # the same stack cannot stop on ice
    assert dry.actors["ego"].accel.min() < -6.0
    # Tyres give at most mu g; drag adds up to 0.0004 * 25^2 m/s^2.
    assert icy.actors["ego"].accel.min() > -(0.2 * 9.81 + 0.0004 * 25.0 ** 2) - 1e-9


def test_ego_follows_an_elevated_road_and_feels_the_grade():
    spec = spec_of("""
scenario hills {
  duration 6 s
  road hills import "curves_elevation.xodr"
  ego car on hills lane -1 at 480 m speed 12 m/s {
    stack bev cruise_speed 12 m/s
  }
}""", base_dir=XODR)
    run = RunState(spec)
    try:
        assert run.scene.elevated and run.scene.collision_triangles > 0
        trace = batch._loop([run])[0]
    finally:
        run.physics.close()
    assert trace.status == "ok"
    z, grade = run.ego_road.elevation.at(run.ego_s)
    assert run.ego_z == pytest.approx(z, abs=1e-6) and abs(z) > 1.0
    assert run.ego.pitch == pytest.approx(math.atan(grade), abs=0.01)
    assert np.abs(trace.actors["ego"].lane_offset).max() < 0.5  # lane kept on the hill


def test_camera_imu_gnss_runs_are_deterministic():
    spec = spec_of("""
scenario sensors {
  duration 2 s
  road r {
    line length 300 m
    arc length 100 m curvature 0.01 /m
    lanes right 2 width 3.5 m
  }
  ego car on r lane -1 at 20 m speed 15 m/s {
    stack bev cruise_speed 15 m/s
    sensor lidar rate 10 Hz
    sensor camera rate 5 Hz width 96 height 64
    sensor imu rate 50 Hz
    sensor gnss rate 10 Hz noise 0.5 m
  }
  agent lead car on r lane -1 at 60 m speed 12 m/s {
    behavior cruise speed 12 m/s
  }
}""")
    first, second = X.execute(spec), X.execute(spec)
    assert first.status == "ok", first.error
    assert first.digest == second.digest


@pytest.mark.parametrize("lead_s,visible", [(570.0, True), (650.0, False)])
def test_a_crest_hides_a_truck_from_the_lidar(lead_s, visible):
    # The road climbs from z = 12.6 m at s = 540 m to a crest of 14.6 m at s = 590 m
    # and falls to 12.4 m at 650 m: the crest's collision mesh blocks the rays.
    spec = spec_of(f"""
scenario crest {{
  duration 0.1 s
  road hills import "curves_elevation.xodr"
  ego car on hills lane -1 at 540 m speed 0 m/s {{
    stack bev
    sensor lidar rate 10 Hz rays 2048 channels 8 range 150 m vfov 8 deg
  }}
  agent lead truck on hills lane -1 at {lead_s} m speed 0 m/s {{
    behavior cruise speed 0 m/s
  }}
}}""", base_dir=XODR)
    run = RunState(spec)
    try:
        batch._loop([run])
        frame = run.sensors["lidar"].capture(run, 0.1)
        hits = int((frame.data["hit_body"] == run.physics.bodies["lead"]).sum())
        # Without the road surface the truck would be in plain view.
        for body in run.physics.ground_ids - {run.physics.ground}:
            run.physics.p.removeBody(body, physicsClientId=run.physics.client)
        bare = int((run.sensors["lidar"].capture(run, 0.1).data["hit_body"] == run.physics.bodies["lead"]).sum())
    finally:
        run.physics.close()
    assert bare > 20
    assert (hits > 20) if visible else (hits == 0)


@pytest.mark.parametrize("road_m, left", [(120.0, True), (400.0, False)])
def test_driving_past_the_end_of_the_road_is_an_event(road_m, left):
    # 20 m/s for 6 s from station 10 m: 130 m, past the end of a 120 m road, not of 400 m.
    spec = spec_of(f"""scenario end {{
  duration 6 s
  road r {{
    line length {road_m} m
    lanes right 1
  }}
  ego car on r lane -1 at 10 m speed 20 m/s {{
    stack bev cruise_speed 20 m/s
  }}
  expect {{
    stay in lane
  }}
}}""")
    result = X.execute(spec)
    trace = result.trace
    events = trace.events_of("left_road")
    assert len(events) == int(left)
    if left:
        e = events[0]
        assert e.detail == {"actor": "ego", "road": "r", "s": 120.0}
        # Half the car's length past the end: (120 + 2.3 - 10) m at 20 m/s, within a step or two.
        assert e.time_s == pytest.approx((120.0 + 2.3 - 10.0) / 20.0, abs=0.05)
        assert trace.actors["ego"].s.max() == pytest.approx(120.0)
        # In no lane from then on: lane keeping is unknown there, and fails.
        off = trace.time >= e.time_s
        assert np.isnan(trace.actors["ego"].lane_offset[off]).all()
        assert not np.isnan(trace.actors["ego"].lane_offset[~off]).any()
    assert result.verdicts[0].passed is not left
