"""Closed loop: faults change runs the way their outcome class says; nothing crashes a sweep."""

from __future__ import annotations

import pytest

from addt_dsl.compiler import compile_source
from addt_dsl.runtime.execute import execute
from addt_dsl.runtime.executor import run_local
from addt_dsl.runtime.outcome import GoldenCache, classify, classify_many, golden_spec
from addt_dsl.sweep import expand
from tests.conftest import EXAMPLES

pytestmark = pytest.mark.slow


def specs(faults: str, duration_s: float = 4.0, family: str = "following", extra: str = "", sweep: str = ""):
    src = (f"scenario t {{\n  duration {duration_s} s\n  step 10 ms\n  seed 5\n"
           f'  include "families/{family}.addt"\n{extra}\n  faults {{\n{faults}\n  }}\n{sweep}\n}}\n')
    result = compile_source(src, "t.addt", base_dir=EXAMPLES / "suites")
    assert result.ok, result.diagnostics
    return expand(result.plan).specs


def spec(*a, **kw):
    return specs(*a, **kw)[0]


def fault_events(result):
    return [e for e in result.trace.events if e.kind == "fault"]


def test_a_blind_ego_collides_and_is_a_hazard():
    s = spec("    drop lidar rate 100 %", duration_s=6.0,
             extra="  param dummy = 0 in [0, 1]")  # following: 22 m/s towards a 15 m/s lead, 40 m ahead
    result, outcome = classify(s, cache=GoldenCache())
    assert outcome == "hazard" and "no_collision" in result.failed_oracles
    assert any(e.kind == "collision" for e in result.trace.events)
    assert all(e.detail["value"] == e.time_s for e in fault_events(result))  # every lost frame, stamped


def test_a_blind_ego_whose_fault_free_twin_also_fails_is_twin_failed_not_hazard():
    # The same collision as above, but an oracle the scenario fails without any fault
    # (the ego never reaches 40 m/s): the run says nothing about the fault.
    s = spec("    drop lidar rate 100 %", duration_s=6.0,
             extra="  param dummy = 0 in [0, 1]\n  expect {\n    fast: eventually ego.speed > 40 m/s\n  }")
    golden = execute(golden_spec(s))
    assert "fast" in golden.failed_oracles and "no_collision" not in golden.failed_oracles
    result, outcome = classify(s, cache=GoldenCache())
    assert "no_collision" in result.failed_oracles
    assert outcome == "twin_failed"


def test_a_flip_in_the_last_mantissa_bit_of_the_path_length_is_masked():
    s = spec("    at 1 s bitflip planner.path_length bit 0")
    result, outcome = classify(s, cache=GoldenCache())
    (event,) = fault_events(result)
    assert event.detail["location"] == "planner.path_length" and event.detail["bit"] == 0
    assert 0 < abs(event.detail["value"] - event.detail["before"]) < 1e-13  # one ulp of 66 m
    assert outcome == "masked"


def test_a_flip_that_turns_an_infinite_cost_into_nan_picks_a_colliding_plan_silently():
    # At 1 s the first candidate (cruise speed) is predicted to collide: cost +inf. Flipping
    # a mantissa bit of inf gives NaN, and NaN wins every `cost < best` comparison after it.
    s = spec("    at 1 s bitflip planner.cost bit 0")
    result, outcome = classify(s, cache=GoldenCache())
    (event,) = fault_events(result)
    assert event.detail["before"] == float("inf") and event.detail["value"] != event.detail["value"]
    assert outcome == "silent"


def test_late_frames_change_the_outputs_without_failing_an_oracle_silent():
    s = spec("    delay lidar by 60 ms")  # under the 150 ms stale threshold: used, but late
    result, outcome = classify(s, cache=GoldenCache())
    assert result.passed and outcome == "silent"


def test_delays_past_the_stale_threshold_are_effective_drops():
    s = spec("    during [1 s, 3 s] delay lidar by 200 ms")
    result = execute(s)
    stale = [e for e in result.trace.events if e.kind == "stale_frame"]
    assert len(stale) == 21 and all(e.detail["age_s"] == pytest.approx(0.2) for e in stale)


def test_a_count_flipped_to_infinity_is_detected_not_a_crash():
    # The lead is the only object: count 1.0 has exponent 0x3FF; bit 62 makes it +inf.
    s = spec("    at 2 s bitflip perception.count bit 62")
    result, outcome = classify(s, cache=GoldenCache())
    (event,) = fault_events(result)
    assert event.detail["before"] == 1.0 and event.detail["value"] == float("inf")
    assert outcome == "detected" and result.status == "detected" and "OverflowError" in result.error


def test_nan_from_a_bit_flip_in_a_command_trips_the_watchdog():
    # Ego 1.5 m/s under its cruise speed: the PID asks for ~1.5 m/s^2, in [1, 2), whose
    # exponent is 0x3FF; setting bit 62 makes the exponent all ones: NaN (or inf).
    s = spec("    at 0.3 s bitflip control.accel bit 62", family="following",
             extra="", sweep="  sweep {\n    grid ego_speed in [23.5] m/s\n    grid gap in [70] m\n  }")
    result, outcome = classify(s, cache=GoldenCache())
    (event,) = fault_events(result)
    assert 1.0 <= abs(event.detail["before"]) < 2.0
    assert outcome == "detected" and "StackError" in result.error and "non-finite command" in result.error
    assert any(e.kind == "stack_error" for e in result.trace.events)


def test_a_sweep_with_failing_stacks_runs_to_the_end():
    bad = spec("    at 2 s bitflip perception.count bit 62")
    good = spec("    at 2 s bitflip perception.count bit 0")
    good = good.model_copy(update={"run_id": "z"})
    results = run_local([bad, good], jobs=2)
    assert [r.status for r in results] == ["detected", "ok"]


def test_classify_many_matches_classify_and_runs_each_golden_once():
    many = specs("    during [0.5 s, 3 s] bitflip control count n field exponent",
                 extra="  param n = 1 in [1, 5]",
                 sweep="  sweep {\n    grid n in [1, 3]\n    repeat 2\n  }", duration_s=3.0)
    # `n` only feeds the fault: the cells are paired, two scenarios with one twin each.
    assert len(many) == 4 and len({golden_spec(s).key() for s in many}) == 2
    cache = GoldenCache()
    pairs = classify_many(many, jobs=2, cache=cache)
    assert cache.runs == 2
    again = classify_many(many, jobs=1, cache=cache)
    assert cache.runs == 2  # all goldens cached
    one_by_one = [classify(s, cache=GoldenCache())[1] for s in many]
    assert [o for _, o in pairs] == [o for _, o in again] == one_by_one
    assert [r.digest for r, _ in pairs] == [r.digest for r, _ in again]


def test_golden_runs_are_stepped_as_a_batch_with_the_fingerprints_of_runs_alone(monkeypatch, tmp_path):
    from addt_dsl.runtime import outcome

    faulty = [spec("    at 1 s for 1 s drop lidar rate 100 %", duration_s=2.0),
              spec("    at 1 s for 1 s drop lidar rate 100 %", duration_s=2.0, family="curve"),
              spec("    at 1 s for 1 s drop lidar rate 100 %", duration_s=2.0)]
    faulty[2] = faulty[2].model_copy(update={"run_id": "again"})
    goldens = [golden_spec(s) for s in faulty]
    assert len({g.key() for g in goldens}) == 2  # the first and third share their twin
    alone = [outcome.golden_fingerprint(g) for g in goldens]
    sizes = []
    real = outcome.execute_batch
    monkeypatch.setattr(outcome, "execute_batch", lambda specs, **kw: sizes.append(len(specs)) or real(specs, **kw))
    records = outcome.GoldenRun().run_batch(goldens, [0, 1, 2])
    assert sizes == [3]
    got = [outcome.Fingerprint.from_bytes(__import__("base64").b64decode(r.stats["fingerprint"])) for r in records]
    assert [g.to_bytes() for g in got] == [a.to_bytes() for a in alone]
    # A worker missing its goldens in the store runs them as one batch, once per twin.
    sizes.clear()
    cache = GoldenCache(tmp_path / "golden.sqlite")
    assert [fp.to_bytes() for fp in cache.goldens(faulty)] == [a.to_bytes() for a in alone]
    assert sizes == [2] and cache.runs == 2
    assert cache.goldens(faulty) and cache.runs == 2 and sizes == [2]
