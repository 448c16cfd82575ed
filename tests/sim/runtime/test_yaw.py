"""`yaw` is the body's heading relative to its lane while the actor stands still from the
start; once it moves, its body follows its path (the lane, a walk across it): a car parked
at 15 deg that drives off is drawn along the lane, a cyclist crossing to +y is drawn at
+90 deg whatever yaw it was placed with."""

import math

import numpy as np
import pytest

from addt_dsl.compiler import compile_source
from addt_dsl.runtime import agents as array_agents
from addt_dsl.runtime.execute import execute
from addt_dsl.sweep import expand

pytestmark = pytest.mark.slow

SOURCE = """
scenario yawed {
  duration 6 s
  road r {
    line length 300 m
    lanes right 2 left 1 width 3.5 m
  }
  ego car on r lane -2 at 10 m speed 0 m/s {
    stack bev cruise_speed 0 m/s
  }
  agent parked car on r lane -1 at 60 m yaw 15 deg {
    at 2 s behavior cruise speed 10 m/s
  }
  agent crosser cyclist on r lane -1 at 120 m yaw 90 deg {
    at 1 s behavior cross speed 3 m/s direction left
  }
  agent angled car on r lane 1 at 200 m yaw -10 deg
}
"""


@pytest.mark.parametrize("arrays", [False, True], ids=["one_by_one", "arrays"])
def test_yaw_holds_while_standing_and_the_path_takes_over_once_moving(arrays, monkeypatch):
    if arrays:  # the agents posed as arrays, as with many agents (and stepped by the kernel)
        monkeypatch.setattr(array_agents, "ARRAY_MIN_AGENTS", 1)
    else:  # posed and stepped one by one
        monkeypatch.setattr(array_agents.Fleets, "_step_arrays", lambda self, items: items)
    result = compile_source(SOURCE)
    assert result.plan is not None, [str(d) for d in result.diagnostics]
    tr = execute(expand(result.plan).specs[0]).trace
    k = int(round(1.5 / tr.period_s))
    parked, crosser, angled = (tr.actors[n] for n in ("parked", "crosser", "angled"))
    # Standing: the declared yaw on the lane's direction (+x for lane -1, -x for lane 1).
    assert parked.heading[k] == pytest.approx(math.radians(15.0))
    assert crosser.heading[0] == pytest.approx(math.radians(90.0))
    assert np.allclose(np.cos(angled.heading - (math.pi - math.radians(10.0))), 1.0)
    # Moving: along the lane (the parked car cruising), across it (the cyclist walking +y).
    moving = parked.speed > 0.0
    assert moving.any() and np.allclose(parked.heading[moving], 0.0, atol=1e-9)
    walking = crosser.speed > 0.0
    assert walking.any() and np.allclose(crosser.heading[walking], math.pi / 2, atol=1e-9)
    assert crosser.y[-1] > crosser.y[0] + 3.0
    # Once moved, a stop does not bring the yaw back (the cyclist stops past the road edge).
    first = int(np.flatnonzero(walking)[0])
    assert np.allclose(crosser.heading[first:], math.pi / 2, atol=1e-9)
