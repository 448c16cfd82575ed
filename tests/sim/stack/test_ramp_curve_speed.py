"""The planner's curve speed cap on a route through a ramp (esmini's soderleden.xodr: road 1
bends at 45 m radius into the on-ramp road 5 and the highway): the ego slows for the bend
and keeps to its lane, its lateral acceleration under `max_lateral_accel`."""

import numpy as np
import pytest

from addt_dsl.compiler import compile_source
from addt_dsl.runtime.execute import execute
from addt_dsl.sweep import expand
from tests.sim.conftest import EXAMPLES

pytestmark = pytest.mark.slow

RAMP = """
scenario ramp_curve {
  duration 8 s
  road highway import "maps/soderleden.xodr" road 1
  ego car on highway route 1 -> 5 -> 0 lane -1 at 0 m speed 12 m/s {
    stack bev cruise_speed 25 m/s MAX_LAT
  }
}
"""


def _run(max_lat: str = ""):
    result = compile_source(RAMP.replace("MAX_LAT", max_lat), "ramp.addt", base_dir=EXAMPLES)
    assert result.ok, [d.message for d in result.diagnostics]
    spec = expand(result.plan).specs[0]
    return execute(spec).trace.actors["ego"], spec


@pytest.mark.parametrize("a_lat", [4.0, 2.5])
def test_the_ego_slows_for_the_ramp_bend_and_keeps_its_lane(a_lat):
    ego, _ = _run(f"max_lateral_accel {a_lat} m/s^2")
    dt = 0.01
    # Lateral acceleration from the course: v * d(heading)/dt (0.2 s smoothing of the
    # controller's ripple).
    rate = np.gradient(np.unwrap(ego.heading), dt)
    a = np.convolve(ego.speed * rate, np.ones(20) / 20, mode="same")
    bend = ego.s < 90.0  # road 1 and the ramp's bends (curvature up to 1/45 m at s = 20 m)
    assert np.abs(a[bend][10:-10]).max() < a_lat + 0.5
    assert np.abs(ego.t[bend]).max() < 0.5  # [m] in its lane
    # The cap is sqrt(a_lat / kappa) at the tightest point: 13.4 m/s at 4 m/s^2, 10.6 at 2.5.
    tight = np.abs(ego.s - 20.0) < 3.0
    assert ego.speed[tight].max() < np.sqrt(a_lat * 45.0) + 0.5
    assert ego.speed[-1] > 18.0  # and speeds up on the straight highway
