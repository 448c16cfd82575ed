"""Traffic behaviours, pedestrians, cyclists and collisions in short closed-loop runs."""

import numpy as np
import pytest

from tests.sim import kit

pytestmark = pytest.mark.slow

# A slow ego far behind in the rightmost lane keeps out of the agents' way.
TEMPLATE = """
scenario traffic {{
  duration {duration} s
  road r {{
    line length 600 m
    lanes right 3 width 3.5 m
  }}
  ego car on r lane -3 at 5 m speed 5 m/s {{
    stack bev cruise_speed 5 m/s
  }}
{agents}
}}
"""


def run(agents: str, duration: float = 8.0):
    return kit.run(TEMPLATE.format(agents=agents, duration=duration))


def lane_t(lane: int) -> float:
    return -3.5 * (-lane) + 1.75


def test_cruise_reaches_its_speed():
    tr = run("agent a car on r lane -1 at 50 m speed 10 m/s {\n behavior cruise speed 20 m/s\n}")
    assert tr.actors["a"].speed[-1] == pytest.approx(20.0, abs=0.1)


def test_idm_follows_a_slow_leader_at_a_safe_gap():
    tr = run("""agent lead car on r lane -1 at 100 m speed 8 m/s {
  behavior cruise speed 8 m/s
}
agent f car on r lane -1 at 60 m speed 16 m/s {
  behavior idm speed 20 m/s time_gap 1.5 s min_gap 2 m
}""", duration=10.0)
    lead, f = tr.actors["lead"], tr.actors["f"]
    gap = lead.s - f.s - 4.6
    assert gap.min() > 2.0
    assert f.speed[-1] == pytest.approx(8.0, abs=1.0)
    assert not tr.events_of("collision")


def test_sudden_brake_when_triggered():
    tr = run("""agent a car on r lane -1 at 50 m speed 15 m/s {
  behavior cruise speed 15 m/s
  when a.s > 80 m then behavior brake decel 6 m/s^2
}""")
    a = tr.actors["a"]
    fired = [e for e in tr.events_of("trigger") if e.detail["actor"] == "a"]
    assert len(fired) == 1
    k = int(round(fired[0].time_s / tr.period_s))
    assert a.speed[k + 50] == pytest.approx(15.0 - 6.0 * 0.5, abs=0.1)
    assert a.speed[-1] == 0.0


def test_lane_change_and_cut_in_end_in_their_lanes():
    tr = run("""agent lc car on r lane -2 at 40 m speed 10 m/s {
  behavior cruise speed 10 m/s
  behavior lane_change to -1 duration 4 s
}
agent cut car on r lane -2 at 80 m speed 10 m/s {
  behavior cruise speed 10 m/s
  when cut.s > 90 m then behavior cut_in to -3 duration 2 s
}""")
    lc, cut = tr.actors["lc"], tr.actors["cut"]
    assert lc.t[-1] == pytest.approx(lane_t(-1), abs=1e-6)
    assert cut.t[-1] == pytest.approx(lane_t(-3), abs=1e-6)
    # Cut-in is twice as abrupt: larger peak yaw relative to the road.
    assert np.abs(cut.heading).max() > 1.5 * np.abs(lc.heading).max() > 0.0


def test_overtake_passes_and_returns_to_its_lane():
    tr = run("""agent slow car on r lane -2 at 60 m speed 8 m/s {
  behavior cruise speed 8 m/s
}
agent fast car on r lane -2 at 30 m speed 14 m/s {
  behavior cruise speed 14 m/s
  when distance(fast, slow) < 20 m then behavior overtake speed 16 m/s target slow margin 8 m
}""", duration=10.0)
    slow, fast = tr.actors["slow"], tr.actors["fast"]
    assert fast.t.max() == pytest.approx(lane_t(-1), abs=0.01)  # used the passing lane
    assert fast.t[-1] == pytest.approx(lane_t(-2), abs=1e-6)  # and came back
    assert fast.s[-1] - slow.s[-1] > 8.0 + 4.6
    assert not tr.events_of("collision")


def test_pedestrian_crosses_and_cyclist_rides():
    tr = run("""agent ped pedestrian on r lane -1 at 150 m offset 2.5 m {
  behavior cross speed 1.4 m/s direction right beyond 1 m
}
agent bike cyclist on r lane -1 at 40 m speed 5 m/s offset -1 m {
  behavior cruise speed 6 m/s
}
agent jogger pedestrian on r lane -3 at 100 m offset -3 m {
  behavior walk speed 2 m/s heading 30 deg
}""", duration=10.0)
    ped, bike, jog = tr.actors["ped"], tr.actors["bike"], tr.actors["jogger"]
    assert (jog.t[-1] - jog.t[0]) / (jog.s[-1] - jog.s[0]) == pytest.approx(np.tan(np.radians(30.0)))
    assert jog.speed[-1] == pytest.approx(2.0, abs=0.01)
    assert ped.t[0] == pytest.approx(lane_t(-1) + 2.5)
    assert ped.s[-1] == pytest.approx(150.0, abs=1e-6)
    # 10 s at up to 1.4 m/s across a 10.5 m road: still crossing, heading across it.
    assert ped.t[-1] < ped.t[0] - 10.0
    assert ped.heading[-1] == pytest.approx(-np.pi / 2)
    assert bike.speed[-1] == pytest.approx(6.0, abs=0.05)
    assert bike.t[-1] == pytest.approx(lane_t(-1) - 1.0)


def test_agents_colliding_with_each_other_are_recorded_and_the_run_goes_on():
    tr = run("""agent stopped car on r lane -1 at 100 m speed 0 m/s {
  behavior cruise speed 0 m/s
}
agent rammer truck on r lane -1 at 60 m speed 15 m/s {
  behavior cruise speed 15 m/s
}""", duration=6.0)
    hits = tr.events_of("collision")
    assert [sorted(e.detail["actors"]) for e in hits] == [["rammer", "stopped"]]
    # 40 m - half lengths (2.3 + 6) at 15 m/s: contact at ~2.11 s.
    assert hits[0].time_s == pytest.approx((40.0 - 8.3) / 15.0, abs=0.02)
    assert tr.duration_s == pytest.approx(6.0)  # only ego collisions end a run
    assert tr.actors["stopped"].clearance.min() < 0.0
