"""A scripted ego (behaviours and steps, as an agent's) moves as the agents' code moves
agents, recorded like the stack-driven ego: checked against hand calculations of the
loop's kinematics (speed first, then position: v += a dt, s += v dt)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from addt_dsl.compiler import compile_source
from addt_dsl.diagnostics import render_text
from addt_dsl.runtime.execute import execute
from addt_dsl.sweep import expand
from tests.sim.kit import first_run

DT = 0.01


def _run(source: str):
    return first_run(source, "scripted.addt")


def _index(run, time_s: float) -> int:
    return int(round(time_s / DT))


CRUISE = """
scenario cruise {
  duration 5 s
  step 10 ms
  road r {
    line length 400 m
    lanes right 2
  }
  ego car on r lane -1 at 10 m speed 15 m/s {
    %s
    behavior cruise speed 15 m/s
  }
  agent lead car on r lane -2 at 30 m speed 10 m/s
  expect {
    slow: always speed(ego) < 15.01 m/s
    short: always s(ego) < 70.05 m
    no collision
  }
}
"""


def test_cruising_ego_matches_hand_calculation_and_oracles_judge_it():
    run = _run(CRUISE % "")
    ego = run.trace.actors["ego"]
    t = run.trace.time
    assert run.status == "ok" and len(t) == 501
    # s0 + v t on a straight road along x, in the centre of lane -1 (t = -1.75 m).
    assert np.max(np.abs(ego.s - (10.0 + 15.0 * t))) < 1e-6
    assert np.max(np.abs(ego.x - (10.0 + 15.0 * t))) < 1e-6
    assert np.all(ego.y == -1.75) and np.all(ego.t == -1.75) and np.all(ego.lane_offset == 0.0)
    assert np.all(ego.speed == 15.0) and np.all(ego.accel == 0.0) and np.all(ego.heading == 0.0)
    # No stack: nothing runs, nothing is commanded.
    assert not run.trace.latency["e2e"].any() and not run.trace.outputs["control.accel"].any()
    verdicts = {v.name: v for v in run.verdicts}
    assert verdicts["slow"].passed and verdicts["no_collision"].passed
    # s = 10 + 15 t passes 70.05 m between 4.00 s (70.00 m) and 4.01 s (70.15 m).
    assert not verdicts["short"].passed and verdicts["short"].first_violation_s == pytest.approx(4.01, abs=1e-9)


def test_same_spec_same_digest_and_an_open_loop_stack_changes_no_motion():
    first, second = _run(CRUISE % ""), _run(CRUISE % "")
    assert first.digest == second.digest
    with_stack = _run(CRUISE % "stack bev cruise_speed 30 m/s")
    assert _run(CRUISE % "stack bev cruise_speed 30 m/s").digest == with_stack.digest
    a, b = first.trace.actors["ego"], with_stack.trace.actors["ego"]
    for field in ("x", "y", "heading", "speed", "s", "t"):
        assert np.array_equal(getattr(a, field), getattr(b, field)), field
    # The stack ran on the scripted world: it wants 30 m/s, so it commands throttle (recorded only).
    assert with_stack.trace.outputs["control.accel"].max() > 0.5
    assert with_stack.trace.latency["e2e"].max() > 0.0


BRAKE = """
scenario brake {
  duration 8 s
  step 10 ms
  road r {
    line length 400 m
    lanes right 1
  }
  ego car on r lane -1 at 10 m speed 20 m/s {
    behavior cruise speed 20 m/s
    at 1 s behavior brake decel 4 m/s^2
  }
}
"""


def test_braking_ego_matches_hand_calculation():
    run = _run(BRAKE)
    ego = run.trace.actors["ego"]
    # 1 s at 20 m/s, then n steps at -4 m/s^2: v_n = 20 - 4 n dt, s_n = s_1 + dt sum v_i
    # = 30 + 20 n dt - 4 dt^2 n (n + 1) / 2, down to standstill at n = 500 (79.9 m).
    for n in (0, 1, 100, 250, 499, 500):
        k = _index(run, 1.0) + n
        assert ego.speed[k] == pytest.approx(20.0 - 4.0 * n * DT, abs=1e-9)
        assert abs(ego.s[k] - (30.0 + 20.0 * n * DT - 4.0 * DT * DT * n * (n + 1) / 2)) < 1e-6
    assert ego.speed[_index(run, 6.0)] < 1e-9 and np.all(ego.speed[_index(run, 6.0) + 1:] == 0.0)
    assert abs(ego.s[-1] - 79.9) < 1e-6
    assert ego.accel[_index(run, 2.0)] == -4.0


TRIGGER = """
scenario trigger {
  duration 10 s
  step 10 ms
  road r {
    line length 400 m
    lanes right 1
  }
  ego car on r lane -1 at 10 m speed 20 m/s {
    behavior cruise speed 20 m/s
    when gap(ego, lead) < 30 m then behavior brake decel 5 m/s^2
  }
  agent lead car on r lane -1 at 101.23 m speed 10 m/s
  expect {
    no collision
    min gap to lead 5 m
  }
}
"""


def test_gap_trigger_on_the_ego_fires_at_the_hand_computed_time():
    run = _run(TRIGGER)
    # gap = (101.23 + 10 t) - (10 + 20 t) - 4.6 m = 86.63 - 10 t < 30 m from t > 5.663 s:
    # the first sample is 5.67 s, and the brake acts from that step on.
    fired = [e.time_s for e in run.trace.events if e.kind == "trigger" and e.detail["actor"] == "ego"]
    assert fired == [pytest.approx(5.67, abs=1e-9)]
    ego = run.trace.actors["ego"]
    k = _index(run, 5.67)
    assert ego.speed[k] == 20.0 and ego.speed[k + 1] == pytest.approx(19.95, abs=1e-9)
    # From 20 to 10 m/s at 5 m/s^2: 200 steps closing dt * sum(10 - 0.05 i) = 9.95 m of
    # the 29.93 m gap, the least gap of the run (the ego goes on braking to a stop).
    lead = run.trace.actors["lead"]
    gap = lead.s - ego.s - 4.6
    assert gap[k] == pytest.approx(86.63 - 10.0 * 5.67, abs=1e-6)
    assert ego.speed[k + 200] == pytest.approx(10.0, abs=1e-9)
    assert abs(gap.min() - 19.98) < 1e-6 and abs(gap[k + 200] - 19.98) < 1e-6
    assert all(v.passed for v in run.verdicts), run.verdicts


COLLIDE = """
scenario collide {
  duration 10 s
  step 10 ms
  road r {
    line length 400 m
    lanes right 1
  }
  ego car on r lane -1 at 10 m speed 10 m/s {
    behavior cruise speed 10 m/s
  }
  agent parked car on r lane -1 at 54.6 m speed 0 m/s
  expect {
    no collision
  }
}
"""


def test_a_scripted_ego_collides_as_the_stack_driven_one_does():
    run = _run(COLLIDE)
    # Bumpers touch when 10 + 10 t = 54.6 - 4.6 m: t = 4 s; the run ends at the contact.
    hits = [e for e in run.trace.events if e.kind == "collision"]
    assert len(hits) == 1 and hits[0].detail["actors"] == ["ego", "parked"]
    assert hits[0].time_s == pytest.approx(4.0, abs=0.011)
    assert not run.verdicts[0].passed


MAPS = Path(__file__).resolve().parents[3] / "examples" / "maps"

# The same script on the ego, or on an agent (the ego then parked out of the way on
# another road): the scripted ego is moved by the agents' code, so both record the same
# motion bit for bit, on a route through a junction, with an offset, a lane id driven
# against s (lane 1 of road 0) and a named step that another step waits for.
ROUTED = """
scenario routed {
  duration 14 s
  step 10 ms
  road town import "fabriksgatan.xodr" road 0
  %s car on town route 0 -> left lane 1 at 40 m speed 8 m/s offset 0.3 m {
    behavior cruise speed 10 m/s accel 1 m/s^2
    slow: at 4 s behavior brake decel 2 m/s^2 to_speed 5 m/s
    when ended(%s.slow) then behavior speed_profile times [0 s, 3 s] speeds [5 m/s, 9 m/s]
  }
  %s car on town route 2 lane -1 at 150 m speed 0 m/s
}
"""


def test_a_scripted_ego_moves_exactly_as_an_agent_with_its_script():
    def run(scripted: str, parked: str):
        result = compile_source(ROUTED % (scripted, scripted.split()[-1], parked), path="routed.addt",
                                base_dir=MAPS)
        assert result.ok, render_text(result.diagnostics, result.sources)
        return execute(expand(result.plan).specs[0])

    as_ego = run("ego", "agent parked")
    as_agent = run("agent twin", "ego")
    ego, twin = as_ego.trace.actors["ego"], as_agent.trace.actors["twin"]
    for field in ("x", "y", "heading", "speed", "accel", "s", "t", "lane_offset"):
        assert np.array_equal(getattr(ego, field), getattr(twin, field)), field
    assert ego.frame == twin.frame and np.array_equal(as_ego.trace.steps["ego.slow"], as_agent.trace.steps["twin.slow"])
    # It turned left through the junction (a quarter turn) and kept its offset.
    assert abs(abs(ego.heading[-1] - ego.heading[0]) - np.pi / 2) < 0.2
    assert abs(ego.t[-1] - ego.t[0]) < 1e-9 and abs(ego.lane_offset[0] - 0.3) < 1e-9


LIGHTS = """
scenario lit {
  duration 25 s
  step 10 ms
  road r {
    line length 400 m
    lanes right 2
  }
  lights {
    signal s1 road r at 150 m
    controller main signals [s1] green 5 s yellow 3 s red 30 s
  }
  ego car on r lane -2 at 10 m speed 10 m/s %s {
    behavior cruise speed 10 m/s
  }
  expect {
    no red_light
  }
}
"""


def test_a_scripted_ego_meets_traffic_lights_as_agents_do():
    """It stops at red like an agent (its front short of the line), unless `at_red run`;
    `no red_light` judges it either way."""
    stops = _run(LIGHTS % "")
    ego = stops.trace.actors["ego"]
    assert stops.verdicts[0].passed and ego.speed[-1] < 0.1
    front = ego.s[-1] + 2.3
    assert 145.0 < front <= 150.0 and np.all(stops.trace.red_margin["ego"] >= 0.0)
    runs = _run(LIGHTS % "at_red run")
    # At 10 m/s the front (12.3 m at the start) reaches the line at 13.77 s, in red (8 s to 38 s).
    assert np.all(runs.trace.actors["ego"].speed == 10.0)
    assert not runs.verdicts[0].passed and runs.verdicts[0].first_violation_s == pytest.approx(13.77, abs=0.011)


LIVE = """
scenario live {
  duration 5 s
  step 10 ms
  road r {
    line length 400 m
    lanes right 2
  }
  ego car on r lane -1 at 10 m speed 10 m/s {
    behavior cruise speed speed(lead) + 2 m/s
    at 3 s behavior brake decel 2 m/s^2
  }
  agent lead car on r lane -2 at 60 m speed 10 m/s {
    behavior cruise speed speed(pace)
    at 2 s behavior brake decel 4 m/s^2
  }
  agent pace car on r lane -1 at 200 m speed 10 m/s
}
"""


def test_steps_run_when_a_time_0_behaviour_reads_signals():
    """A time-0 behaviour whose setting reads signals starts on the first recorded state;
    the actor's steps are armed all the same (they were dropped, for agents too)."""
    run = _run(LIVE)
    fired = [(e.detail["actor"], e.detail["behavior"], round(e.time_s, 6)) for e in run.trace.events
             if e.kind == "trigger"]
    assert fired == [("lead", "brake", 2.0), ("ego", "brake", 3.0)]
    lead, ego = run.trace.actors["lead"], run.trace.actors["ego"]
    # Before 2 s the lead holds the pace car's 10 m/s: the ego wants 12 m/s (2 m/s^2, 1 s).
    k2, k3 = _index(run, 2.0), _index(run, 3.0)
    assert np.all(lead.speed[:k2 + 1] == 10.0) and ego.speed[k2] == pytest.approx(12.0, abs=1e-9)
    assert lead.speed[k2 + 50] == pytest.approx(8.0, abs=1e-9) and ego.speed[k3 + 50] < ego.speed[k3]


def _dense(n: int) -> str:
    agents = "\n".join(f"  agent a{i} car on r lane {-1 - i % 2} at {40 + 15 * i} m speed 12 m/s {{\n"
                       f"    behavior idm speed {10 + i % 3} m/s\n  }}" for i in range(n))
    return f"""
scenario dense {{
  duration 8 s
  step 10 ms
  road r {{
    line length 800 m
    lanes right 2
  }}
  ego car on r lane -1 at 10 m speed 18 m/s {{
    behavior idm speed 20 m/s
  }}
{agents}
}}
"""


def test_a_scripted_ego_following_agents_stepped_as_arrays_sees_the_same_leaders(monkeypatch):
    """Agents stepped as arrays leave the leader index stale; the scripted ego, which asks
    it for its leader before the agents move, must see it rebuilt: the same run either way."""
    from addt_dsl.runtime import agents as array_agents

    with monkeypatch.context() as m:  # the agents one by one
        m.setattr(array_agents.Fleets, "_step_arrays", lambda self, items: items)
        one_by_one = _run(_dense(8))
    ego = one_by_one.trace.actors["ego"]
    assert ego.accel.min() < -1.0  # it closes on the agents ahead and brakes for them
    monkeypatch.setattr(array_agents, "ARRAY_MIN_AGENTS", 1)
    assert _run(_dense(8)).digest == one_by_one.digest


# One line per registered behaviour (keyword: the step started at 1 s on the ego).
EVERY_BEHAVIOUR = {
    "brake": "behavior brake decel 3 m/s^2",
    "cross": "behavior cross speed 2 m/s direction left",
    "cruise": "behavior cruise speed 14 m/s",
    "cut_in": "behavior cut_in to -2 duration 2 s",
    "idm": "behavior idm speed 15 m/s",
    "keep_gap": "behavior keep_gap target lead distance 20 m",
    "lane_change": "behavior lane_change to -2 duration 3 s",
    "lane_offset": "behavior lane_offset to -1 m max_lat_accel 1 m/s^2 shape sinusoidal",
    "overtake": "behavior overtake speed 16 m/s target lead lane -2",
    "speed_profile": "behavior speed_profile times [0 s, 2 s] speeds [12 m/s, 8 m/s]",
    "synchronize": "behavior synchronize master lead master_at 150 m target_s 140 m",
    "teleport": "behavior teleport s 100 m t -1.75 m",
    "trajectory": "behavior trajectory s [40 m, 80 m] t [-1.75 m, -5.25 m] speed 10 m/s",
    "walk": "behavior walk speed 2 m/s heading 30 deg",
}

EVERY = """
scenario every {
  duration 6 s
  step 10 ms
  road r {
    line length 400 m
    lanes right 2
  }
  ego car on r lane -1 at 10 m speed 12 m/s {
    at 1 s %s
  }
  agent lead car on r lane -1 at 60 m speed 10 m/s {
    behavior cruise speed 10 m/s
  }
}
"""


@pytest.mark.parametrize("keyword", sorted(EVERY_BEHAVIOUR))
def test_every_behaviour_drives_a_scripted_ego(keyword):
    """Each behaviour in the registry starts on the ego and moves it as an agent would
    (same trace as an agent `twin` with the script, the ego then parked behind)."""
    from addt_dsl.registry import BEHAVIORS

    assert {cls.keyword for cls in BEHAVIORS.classes()} == set(EVERY_BEHAVIOUR)
    as_ego = _run(EVERY % EVERY_BEHAVIOUR[keyword])
    assert as_ego.status == "ok"
    fired = [e.detail["behavior"] for e in as_ego.trace.events if e.kind == "trigger"]
    assert fired == [keyword]
    twin = (EVERY % "behavior cruise speed 0 m/s").replace("ego car on r lane -1 at 10 m speed 12 m/s",
                                                             "ego car on r lane -2 at 300 m speed 0 m/s") \
        .replace("agent lead", "agent twin car on r lane -1 at 10 m speed 12 m/s {\n    at 1 s %s\n  }\n"
                 "  agent lead" % EVERY_BEHAVIOUR[keyword].replace("ego", "twin"))
    as_agent = _run(twin)
    ego, agent = as_ego.trace.actors["ego"], as_agent.trace.actors["twin"]
    for field in ("x", "y", "heading", "speed", "s", "t"):
        assert np.array_equal(getattr(ego, field), getattr(agent, field)), field
