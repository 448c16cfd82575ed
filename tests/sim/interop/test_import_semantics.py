"""What a step computes, checked by hand: defects found by comparing imported OpenSCENARIO
runs with esmini's trajectories, each pinned with a hand calculation."""

import numpy as np
import pytest

from tests.sim.kit import run

pytestmark = pytest.mark.slow

SCENARIO = """
scenario live {{
  duration 6 s
  road r {{
    line length 800 m
    lanes right 3 width 3.5 m
  }}
  ego car on r lane -2 at 10 m speed 0 m/s {{
    stack bev cruise_speed 0 m/s
  }}
  agent a car on r lane -1 at 100 m speed 10 m/s {{
    behavior cruise speed {speed}
    at 2 s behavior brake decel 5 m/s^2
  }}
}}
"""


def scene(name: str, duration: str, actors: str, length_m: int = 800, lanes: str = "right 2") -> str:
    """A scenario on a straight road with a standing stack-driven ego in lane -2 at 10 m."""
    return f"""
scenario {name} {{
  duration {duration}
  road r {{
    line length {length_m} m
    lanes {lanes} width 3.5 m
  }}
  ego car on r lane -2 at 10 m speed 0 m/s {{
    stack bev cruise_speed 0 m/s
  }}
{actors.strip(chr(10))}
}}
"""


@pytest.mark.parametrize("speed", ["10 m/s", "speed(a)"])
def test_a_live_behaviour_at_the_start_keeps_the_actors_steps(speed):
    # An agent whose first behaviour reads a signal (a live setting) lost every step of its
    # script: the brake at 2 s never fired and it cruised on.
    trace = run(SCENARIO.format(speed=speed))
    a = trace.actors["a"]
    k = int(round(4.0 / trace.period_s))
    # 10 m/s until 2 s, then -5 m/s^2: standstill at 4 s, 20 + 10 m from the start.
    assert a.speed[k] == pytest.approx(0.0, abs=0.06)
    assert a.s[k] - a.s[0] == pytest.approx(30.0, abs=0.15)
    assert np.all(a.speed[int(round(1.9 / trace.period_s))] == pytest.approx(10.0, abs=1e-6))


def test_a_trajectory_without_timing_keeps_the_actors_speed():
    # OpenSCENARIO's FollowTrajectoryAction without timing keeps the entity's speed; it ran
    # at a 10 m/s default instead.
    trace = run(scene("walk", "4 s", """
  agent p pedestrian on r lane -1 at 100 m speed 1.5 m/s {
    behavior trajectory s [110, 120] m t [-1.75, -1.75] m
  }
""", length_m=400, lanes="right 2"))
    p = trace.actors["p"]
    k = int(round(3.0 / trace.period_s))
    assert p.speed[k] == pytest.approx(1.5, abs=1e-9)
    assert p.s[k] - p.s[0] == pytest.approx(4.5, abs=1e-6)


def test_direction_reverse_drives_against_the_lane():
    # An entity that faces against its lane (OpenSCENARIO: an Orientation of pi relative to
    # the lane) drives that way: a car overtaking in the oncoming lane, a wrong-way driver.
    trace = run("""
scenario wrong_way {
  duration 4 s
  road r {
    line length 300 m
    lanes left 1 right 1 width 3.5 m
  }
  ego car on r lane -1 at 10 m speed 0 m/s {
    stack bev cruise_speed 0 m/s
  }
  agent over car on r lane 1 at 100 m speed 10 m/s direction reverse
  agent oncoming car on r lane 1 at 200 m speed 10 m/s
  agent ghost car on r lane -1 at 150 m speed 10 m/s direction reverse
}
""")
    end = len(trace.time) - 1
    for name, x0, y, way in (("over", 100.0, 1.75, 1), ("oncoming", 200.0, 1.75, -1), ("ghost", 150.0, -1.75, -1)):
        a = trace.actors[name]
        assert a.x[end] == pytest.approx(x0 + way * 10.0 * trace.time[end], abs=1e-6), name
        assert a.y[end] == pytest.approx(y, abs=1e-9), name
        assert np.cos(a.heading[end]) == pytest.approx(way, abs=1e-9), name


@pytest.mark.parametrize("setting, want_m", [("distance 20 m", 20.0), ("time_gap 1 s", 25.0)])
def test_keep_gap_is_esminis_damped_spring(setting, want_m):
    # LongitudinalDistanceAction as esmini executes it: a = e * k - (v - v_target) * 2 sqrt(k)
    # with k = 0.4 * (max deceleration when the gap is too long, else max acceleration), the
    # time gap at the target's speed. Gap error e = +0.5 m, decel 5: k = 2, a = 1 m/s^2 on
    # the first step, plus 0.1 m/s slower * 2 sqrt 2.
    gap = want_m + 0.5
    trace = run(f"""
scenario follow {{
  duration 1 s
  road r {{
    line length 800 m
    lanes right 2 width 3.5 m
  }}
  ego car on r lane -2 at 10 m speed 0 m/s {{
    stack bev cruise_speed 0 m/s
  }}
  agent follower car on r lane -1 at 100 m speed 24.9 m/s {{
    behavior keep_gap target lead {setting} accel 3 m/s^2 decel 5 m/s^2
  }}
  agent lead car on r lane -1 at {100 + 4.6 + gap} m speed 25 m/s
}}
""")
    f = trace.actors["follower"]
    expected = 0.5 * 2.0 - (24.9 - 25.0) * 2.0 * np.sqrt(2.0)
    assert (f.speed[1] - f.speed[0]) / trace.period_s == pytest.approx(expected, abs=1e-6)


def test_edges_and_delays_of_a_step_condition():
    # OpenSCENARIO's conditionEdge and delay: an edge never counts at the first evaluation
    # (a condition true from the start does not fire `rising`), and a delay fires that long
    # after the condition counted. The car ramps 0 -> 10 m/s at 2 m/s^2 (speed > 5 m/s
    # from 2.5 s): `rising` + 1 s delay fires at 3.5 s; the level `speed < 1` fires at 0 s.
    trace = run(scene("edges", "6 s", """
  agent a car on r lane -1 at 100 m speed 0 m/s {
    behavior cruise speed 10 m/s accel 2 m/s^2
    up: when rising speed(a) > 5 m/s delayed 1 s then behavior brake decel 1 m/s^2 to_speed 1 m/s
    never: when rising speed(a) < 1 m/s then behavior brake decel 1 m/s^2
    level: when speed(a) < 1 m/s then behavior cruise speed 10 m/s accel 2 m/s^2
  }
""", length_m=800, lanes="right 2"))
    fired = {e.detail["behavior"]: e.time_s for e in trace.events if e.kind == "trigger"}
    starts = {name: float(trace.time[np.flatnonzero(v >= 1)[0]]) if (v >= 1).any() else None
              for name, v in trace.steps.items()}
    assert starts["a.level"] == pytest.approx(0.0)
    assert starts["a.never"] is None
    assert starts["a.up"] == pytest.approx(3.5, abs=trace.period_s + 1e-9)
    assert "brake" in fired


def test_a_lane_change_splits_the_ground_covered_into_along_and_across():
    # Speed is along the actor's own path: during a lane change part of it goes across the
    # road (esmini moves an entity along its heading). 10 m/s, a linear 3.5 m change over
    # 1 s: 3.5 m/s across, sqrt(100 - 12.25) = 9.3675 m/s along.
    trace = run(scene("change", "3 s", """
  agent a car on r lane -2 at 100 m speed 10 m/s {
    at 1 s behavior lane_change to -1 duration 1 s shape linear
  }
""", length_m=800, lanes="right 2"))
    a = trace.actors["a"]
    k1, k2 = (int(round(t / trace.period_s)) for t in (1.0, 2.0))
    assert a.s[k1] - a.s[0] == pytest.approx(10.0, abs=1e-9)
    assert a.s[k2] - a.s[k1] == pytest.approx(np.sqrt(100.0 - 3.5 ** 2), abs=1e-6)
    assert a.t[k2] - a.t[k1] == pytest.approx(3.5, abs=1e-9)


def test_a_timed_trajectory_is_at_each_waypoint_on_time():
    # OpenSCENARIO's timed polyline (position following): on each segment at its length over
    # its duration, whatever the acceleration; a repeated waypoint is a wait; after the last
    # one the speed of the last segment (0 after a wait). It lagged behind its times before
    # (its speed limited to 5 m/s^2 up and 8 m/s^2 down) and drove on at the end.
    trace = run(scene("timed", "5 s", """
  agent a cyclist on r lane -1 at 100 m speed 10 m/s {
    behavior trajectory s [100, 120, 125, 125] m t [-1.75, -1.75, -1.75, -1.75] m times [0, 2, 2.5, 3.5] s
  }
""", length_m=800, lanes="right 2"))
    a = trace.actors["a"]
    at = {t: a.s[int(round(t / trace.period_s))] for t in (1.0, 2.0, 2.25, 3.0, 4.5)}
    assert at[1.0] == pytest.approx(110.0, abs=0.02)
    assert at[2.0] == pytest.approx(120.0, abs=0.11)
    assert at[2.25] == pytest.approx(122.5, abs=0.11)
    assert at[3.0] == pytest.approx(125.0, abs=0.11) and at[4.5] == pytest.approx(at[3.0], abs=1e-9)


def test_end_when_ends_the_run_where_its_condition_fires():
    # `end when C delayed D` (OpenSCENARIO's stop trigger): 10 m/s braking at 5 m/s^2 from
    # 2 s ends at 4 s; the run ends 1 s later, at 5 s, not at its 60 s duration.
    trace = run(scene("ends", "60 s", """
  agent lead car on r lane -1 at 50 m speed 10 m/s {
    stopping: at 2 s behavior brake decel 5 m/s^2
  }
  end when ended(lead.stopping) delayed 1 s
""", length_m=800, lanes="right 2"))
    assert trace.duration_s == pytest.approx(5.0, abs=trace.period_s + 1e-9)
    assert [e.time_s for e in trace.events if e.kind == "end"] == [pytest.approx(trace.duration_s)]


def test_teleport_moves_at_once_and_keeps_the_speed():
    trace = run(scene("jump", "3 s", """
  agent a car on r lane -1 at 100 m speed 10 m/s {
    at 1 s behavior teleport s 300 m t -5.25 m
  }
""", length_m=800, lanes="right 2"))
    a = trace.actors["a"]
    k = int(round(1.0 / trace.period_s))
    assert a.s[k] == pytest.approx(110.0, abs=1e-6)
    # Placed, not moved on in its step (esmini moves no entity an action placed in the step:
    # lane_change_simple's ego is at s = 10.000 the sample after its teleport, 10.25 the next)
    assert a.s[k + 1] == pytest.approx(300.0, abs=1e-6)
    assert a.s[k + 2] == pytest.approx(300.0 + 10.0 * trace.period_s, abs=1e-6)
    assert a.t[k + 1] == pytest.approx(-5.25, abs=1e-9) and a.speed[k + 1] == pytest.approx(10.0)


def test_a_step_repeats_when_its_behaviour_has_ended_and_its_condition_counts_again():
    # OpenSCENARIO's maximumExecutionCount: an event back in standby once its actions ended.
    # The ego speeds up at 1 s and 9 s; `rising speed(ego) > 1 m/s repeat 2` fires at both
    # (1.2 s and 9.2 s: 5 m/s^2 from 0), and a third rise would find no firing left.
    trace = run("""
scenario again {
  duration 20 s
  road r {
    line length 800 m
    lanes right 2 width 3.5 m
  }
  ego car on r lane -2 at 10 m speed 0 m/s {
    behavior cruise speed 0 m/s
    at 1 s behavior cruise speed 5 m/s accel 5 m/s^2
    at 5 s behavior brake decel 5 m/s^2
    at 9 s behavior cruise speed 5 m/s accel 5 m/s^2
    at 13 s behavior brake decel 5 m/s^2
    at 15 s behavior cruise speed 5 m/s accel 5 m/s^2
  }
  agent a car on r lane -1 at 100 m speed 0 m/s {
    when rising speed(ego) > 1 m/s repeat 2 then behavior cruise speed 3 m/s accel 3 m/s^2
    when rising speed(ego) < 1 m/s repeat 3 then behavior brake decel 3 m/s^2
  }
}
""")
    fired = [(round(e.time_s, 2), e.detail["behavior"]) for e in trace.events
             if e.kind == "trigger" and e.detail["actor"] == "a"]
    assert fired == [(1.2, "cruise"), (5.81, "brake"), (9.2, "cruise"), (13.81, "brake")]
