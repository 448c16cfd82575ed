"""An agent's `speed` is the speed along its own path: on a bend, off the reference line,
its station moves by speed / (1 - kappa * t) (the offset curve's length element), so it
covers `speed` metres of ground per second on the outside and the inside of the bend
alike (it covered 10.875 m/s for 10 on the outside of a 40 m radius)."""

import numpy as np
import pytest

from addt_dsl.runtime import agents as array_agents
from tests.sim import kit

pytestmark = pytest.mark.slow

KAPPA = 0.025  # [1/m]: a 40 m radius, turning left

SOURCE = """
scenario arc {
  duration 8 s
  road r {
    arc length 120 m curvature 0.025 /m
    lanes right 2 left 1 width 3.5 m
  }
  ego car on r lane -2 at 110 m speed 0 m/s {
    stack bev cruise_speed 0 m/s
  }
AGENTS
}
"""

CRUISE = """
  agent outer car on r lane -1 at 5 m speed 10 m/s offset -1.75 m {
    behavior cruise speed 10 m/s
  }
  agent inner car on r lane 1 at 100 m speed 10 m/s {
    behavior cruise speed 10 m/s
  }
"""

IDM = """
  agent outer car on r lane -1 at 5 m speed 10 m/s offset -1.75 m {
    behavior idm speed 10 m/s
  }
  agent middle car on r lane -1 at 40 m speed 10 m/s {
    behavior idm speed 10 m/s
  }
"""


def run(agents: str):
    return kit.first_run(SOURCE.replace("AGENTS", agents)).trace


def ground_speed(track, period_s):
    return np.hypot(np.diff(track.x), np.diff(track.y)) / period_s


@pytest.mark.parametrize("arrays", [False, True], ids=["one_by_one", "arrays"])
def test_speed_is_the_speed_along_the_agents_own_path(arrays, monkeypatch):
    if arrays:
        monkeypatch.setattr(array_agents, "ARRAY_MIN_AGENTS", 1)
    else:  # the step one by one too
        monkeypatch.setattr(array_agents.Fleets, "_step_arrays", lambda self, items: items)
    tr = run(CRUISE)
    dt = tr.period_s
    outer, inner = tr.actors["outer"], tr.actors["inner"]
    # Hand calculation: the outer car is 3.5 m right of the reference line (t = -3.5 m) on a
    # 40 m radius, a 43.5 m circle: 10 m/s of ground is 10 / (1 + 0.025 * 3.5) = 9.1954 m/s
    # of station. The inner car drives lane 1 against s, 1.75 m left of the line, on a
    # 38.25 m circle: 10 / (1 - 0.025 * 1.75) = 10.4575 m/s of its path's station.
    assert outer.t[0] == pytest.approx(-3.5)
    assert np.diff(outer.s) / dt == pytest.approx(10.0 / (1.0 + KAPPA * 3.5), rel=1e-9)
    on_road = inner.s[1:] < 119.0
    assert (np.diff(inner.s) / dt)[on_road] == pytest.approx(10.0 / (1.0 - KAPPA * 1.75), rel=1e-6)
    # The ground both cover: 10 m/s (a chord of the arc: within 1e-5).
    assert ground_speed(outer, dt) == pytest.approx(10.0, abs=1e-4)
    assert ground_speed(inner, dt)[on_road] == pytest.approx(10.0, abs=1e-4)


def test_the_array_step_moves_stations_as_the_per_agent_step(monkeypatch):
    with monkeypatch.context() as m:
        m.setattr(array_agents.Fleets, "_step_arrays", lambda self, items: items)  # one by one
        one = run(IDM)
    monkeypatch.setattr(array_agents, "ARRAY_MIN_AGENTS", 1)
    arrays = run(IDM)
    assert one.digest() == arrays.digest()
    outer = one.actors["outer"]
    assert ground_speed(outer, one.period_s) == pytest.approx(outer.speed[1:], abs=1e-4)
