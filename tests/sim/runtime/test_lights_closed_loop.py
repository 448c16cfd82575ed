"""Traffic lights in closed-loop runs: agents and the ego stop at red, runners cross, steps
change lights, the red-light oracle judges, runs stay deterministic."""

import numpy as np
import pytest

from addt_dsl.compiler import compile_file, compile_source
from addt_dsl.plan import LIGHT_STATES
from addt_dsl.runtime.execute import execute
from addt_dsl.runtime.lights import Program, state_at
from addt_dsl.sweep import expand
from tests.sim.conftest import EXAMPLES
from tests.sim.kit import first_run

pytestmark = pytest.mark.slow

INLINE = """
scenario lights {
  duration 22 s
  road r {
    line length 400 m
    lanes right 2
  }
  lights {
    signal s1 road r at 150 m
    controller main signals [s1] green 5 s yellow 3 s red 30 s
    STEPS
  }
  ego car on r lane -1 at 40 m speed 8 m/s {
    stack bev cruise_speed 8 m/s
  }
  agent stopper car on r lane -2 at 60 m speed 10 m/s {
    behavior cruise speed 10 m/s
  }
  agent runner car on r lane -2 at 20 m speed 10 m/s at_red run {
    behavior cruise speed 10 m/s
  }
  expect {
    no red_light
    runner_stops: always red_light(runner) >= 0 m
  }
}
"""


def run_text(text: str):
    return first_run(text, "lights.addt", base_dir=EXAMPLES)


def test_agents_and_the_ego_stop_at_red_and_a_runner_crosses():
    out = run_text(INLINE.replace("STEPS", ""))
    assert out.status == "ok", out.error
    tr = out.trace
    # The trace's light is the program, a pure function of time.
    assert np.array_equal(tr.lights["main"], Program(5.0, 3.0, 30.0).state(tr.time))
    red = tr.lights["main"] == LIGHT_STATES["red"]
    stopper, ego = tr.actors["stopper"], tr.actors["ego"]
    # Both stop with their front bumper within 1.5 m before the line, and stay there at red.
    for track in (stopper, ego):
        front = track.s + 0.5 * track.length_m
        assert front[red].max() <= 150.0
        assert 148.5 <= front[-1] <= 150.0 and track.speed[-1] < 0.1
    assert tr.actors["runner"].s[-1] > 200.0  # `at_red run` drives on through the red
    verdicts = {v.name: v for v in out.verdicts}
    assert verdicts["no_red_light"].passed and 0.0 <= verdicts["no_red_light"].robustness <= 1.5
    runner = verdicts["runner_stops"]
    assert not runner.passed and runner.robustness == pytest.approx(-30.0, abs=0.2)
    # First violation: when the runner's front bumper passes the line at red.
    k = np.argmax(tr.actors["runner"].s + 0.5 * tr.actors["runner"].length_m > 150.0)
    assert runner.first_violation_s == pytest.approx(tr.time[k], abs=0.02)


def test_light_steps_change_the_state_and_the_program_resumes():
    out = run_text(INLINE.replace("STEPS", "at 1 s light main state red\n    at 4 s light main state program"))
    tr = out.trace
    want = state_at(Program(5.0, 3.0, 30.0), [(1.0, "red"), (4.0, "program")], tr.time)
    assert np.array_equal(tr.lights["main"], want)
    assert any(e.kind == "trigger" and e.detail.get("light") == "main" for e in tr.events)


def test_same_run_same_digest():
    text = INLINE.replace("STEPS", "when distance(ego, stopper) < 15 m then light main state red")
    assert run_text(text).digest == run_text(text).digest


def test_steps_and_end_conditions_read_the_red_light_margin_of_their_sample():
    # `red_light(A)` in a condition: the margin as recorded at that sample (conditions read a
    # fixed 100 m before, so a step on it never fired). The light turns red at 8 s, when the
    # stopper, braking since the yellow, is about 10 m short of the line.
    text = INLINE.replace("STEPS", "").replace(
        "    behavior cruise speed 10 m/s\n  }\n  agent runner",
        "    behavior cruise speed 10 m/s\n    when red_light(stopper) < 20 m then behavior cruise speed 3 m/s\n"
        "  }\n  agent runner").replace("  expect {", "  end when red_light(ego) < 5 m\n  expect {")
    assert "speed 3 m/s" in text
    out = run_text(text)
    tr = out.trace
    steps = [e.time_s for e in tr.events if e.kind == "behavior" and e.detail.get("actor") == "stopper"]
    k = int(np.argmax(tr.red_margin["stopper"] < 20.0))
    assert tr.red_margin["stopper"][k - 1] >= 20.0 and steps == [0.0, tr.time[k]]
    assert tr.time[k] == pytest.approx(8.0, abs=0.02)  # red from 8 s: at once
    # The run ends at the first sample the ego's margin is below 5 m (it stops 1 m short).
    assert tr.red_margin["ego"][-1] < 5.0 and (tr.red_margin["ego"][:-1] >= 5.0).all() and tr.time[-1] < 21.0


def test_red_light_runner_example():
    result = compile_file(EXAMPLES / "red_light_runner.addt")
    assert result.ok
    outs = [execute(spec) for spec in expand(result.plan).specs]
    for out in outs:
        v = {x.name: x for x in out.verdicts}
        assert v["no_collision"].passed and v["no_red_light"].passed and v["stopper_stops"].passed
        assert not v["runner_stops"].passed  # the runner runs the red light
        tr = out.trace
        stopper = tr.actors["stopper"]
        assert stopper.speed[-1] < 0.1  # waiting at the light on road 3


def test_a_maps_lights_hold_on_every_road_declared_from_it():
    """The controller names road `town` (road 2 of the map); a car placed on `side`, road 3
    of the same file, still stops at road 3's red light (an import writes one road line
    per starting road)."""
    text = (EXAMPLES / "red_light_runner.addt").read_text().replace(
        'road town import "maps/fabriksgatan_traffic_lights.xodr" road 2',
        'road town import "maps/fabriksgatan_traffic_lights.xodr" road 2\n'
        '  road side import "maps/fabriksgatan_traffic_lights.xodr" road 3').replace(
        "agent stopper car on town route 3", "agent stopper car on side route 3")
    result = compile_source(text, "side.addt", base_dir=EXAMPLES)
    assert result.ok, [d.message for d in result.diagnostics]
    out = execute(expand(result.plan).specs[0])
    assert out.trace.actors["stopper"].speed[-1] < 0.1
    assert {v.name: v.passed for v in out.verdicts}["stopper_stops"]


def test_the_ego_gives_way_at_a_junction_with_yield_gap():
    """`left_turn_yield.addt` (yield_gap 4 s)."""
    plan = compile_file(EXAMPLES / "left_turn_yield.addt").plan
    for spec in expand(plan).specs[1:]:  # the oncoming car at 240 m and 260 m: too close to go first
        out = execute(spec)
        assert out.passed, out.verdicts
        tr = out.trace
        ego, other = tr.actors["ego"], tr.actors["oncoming"]
        entry = 93.7  # road 0's length: the ego's route reaches junction 4 there
        front = ego.s + 0.5 * ego.length_m
        # It gives way: it slows to walking pace at most 8 m into the junction (the
        # oncoming lane's edge; it may creep there) and never stops further in ...
        before = front <= entry + 8.0
        assert ego.speed[before].min() < 2.0  # (260 m: the car clears as the ego arrives: 1.3 m/s)
        waiting = ego.speed < 0.1
        assert not waiting.any() or front[waiting].max() <= entry + 8.0
        k = np.argmax(front > entry + 8.0)
        # ... and crosses the oncoming lane once the oncoming car is past, not before
        assert np.hypot(other.x[k] - ego.x[k], other.y[k] - ego.y[k]) > 5.0
        assert other.y[k] < ego.y[k]  # the oncoming car (driving south) is past the ego
        assert front[-1] > entry + 40.0  # and completes the turn
    # `yield_gap 0 s` turns it off: the same run does not wait at the entry.
    text = (EXAMPLES / "left_turn_yield.addt").read_text().replace("yield_gap 4 s", "yield_gap 0 s")
    base = compile_source(text, "off.addt", base_dir=EXAMPLES).plan
    out = execute(expand(base).specs[2])
    front = out.trace.actors["ego"].s + 0.5 * out.trace.actors["ego"].length_m
    assert (out.trace.actors["ego"].speed[front <= 93.7] > 1.0).all()
