"""`trajectory s [...] t [...]` takes OpenDRIVE road coordinates (s along the reference
line, t left of +s) whichever way the agent's lane runs: on a lane driven against s the
waypoints were read in the agent's path frame (station from its start, offset to the
driver's left of its lane), so it went to the wrong place."""

import numpy as np
import pytest

from addt_dsl.compiler import compile_source
from addt_dsl.runtime.execute import execute
from addt_dsl.sweep import expand

pytestmark = pytest.mark.slow

SOURCE = """
scenario against {
  duration 9 s
  road r {
    line length 400 m
    lanes right 1 left 2 width 3.5 m
  }
  ego car on r lane -1 at 10 m speed 0 m/s {
    stack bev cruise_speed 0 m/s
  }
  agent oncoming car on r lane 1 at 300 m speed 10 m/s {
    behavior trajectory s [260, 220] m t [1.75, 5.25] m speed 10 m/s
  }
  agent along car on r lane -1 at 100 m speed 10 m/s {
    behavior trajectory s [140, 180] m t [-1.75, 1.75] m speed 10 m/s
  }
}
"""


def _passes(track, x_at):
    """(y of the track [m]) where it crosses world x = x_at."""
    return float(np.interp(x_at, *((track.x, track.y) if track.x[-1] > track.x[0] else (track.x[::-1], track.y[::-1]))))


def test_trajectory_waypoints_are_road_coordinates_whichever_way_the_lane_runs():
    result = compile_source(SOURCE)
    assert result.plan is not None, [str(d) for d in result.diagnostics]
    tr = execute(expand(result.plan).specs[0]).trace
    # The road runs along +x from the origin: road (s, t) is world (x, y).
    oncoming, along = tr.actors["oncoming"], tr.actors["along"]
    assert oncoming.x[-1] < oncoming.x[0]  # it drives against s, towards smaller x
    assert _passes(oncoming, 260.0) == pytest.approx(1.75, abs=0.05)
    assert _passes(oncoming, 220.0) == pytest.approx(5.25, abs=0.05)  # in lane 2, road t = 5.25 m
    assert oncoming.y[-1] == pytest.approx(5.25, abs=0.05) and oncoming.x[-1] < 215.0
    # Along s the road frame is the agent's: unchanged.
    assert _passes(along, 180.0) == pytest.approx(1.75, abs=0.05)
