"""Event priorities (OpenSCENARIO 1.2 Event/@priority, esmini's Event::Start): override ends
the other running events of the maneuver, skip does not start while one runs (asked again at
each step), parallel starts anyway. On small synthetic files (tests/unit/interop/priority_kit.py)."""

from __future__ import annotations

from tests.unit.interop.priority_kit import after, at, imported, lane_change, speed


def priority_notes(got) -> list:
    return [d for d in got.diagnostics if "priority" in d.message and d.code != "W0803"]


def car_lines(got) -> list[str]:
    lines = [line.strip() for line in got.text.splitlines()]
    return [line for line in lines if "behavior" in line and not line.startswith("agent")][1:]  # (the ego's first)


def test_one_event_or_events_that_cannot_overlap_translate_without_a_note(tmp_path):
    # Alone; after the other's end; started on simulation times in file order (the lane change,
    # later, cannot run when the speed change starts; it runs in parallel); after a lane change
    # of 2 s from 1 s; an override whose speed action replaces the other's.
    for events in ((speed("ramp", "override", 20, at(1)),),
                   (speed("ramp", "override", 20, at(1)), lane_change("lc", "override", -2, after("ramp"))),
                   (speed("ramp", "skip", 20, at(1)), lane_change("lc", "skip", -2, after("ramp"))),
                   (speed("ramp", "override", 20, at(1)), lane_change("lc", "parallel", -2, at(3))),
                   (lane_change("lc", "override", -2, at(1), duration_s=2.0), speed("ramp", "override", 20, at(3.2))),
                   (speed("ramp", "override", 20, at(1)), speed("hold", "override", 14, at(4), shape="step"))):
        got = imported(tmp_path, *events)
        assert got.plan is not None and not priority_notes(got), got.diagnostics
    assert car_lines(got) == ["at 1 s behavior cruise speed 20 m/s duration 10 s shape linear max_accel 5 m/s^2 "
                              "max_decel 10 m/s^2",
                              "at 4 s behavior cruise speed 14 m/s shape step"]


def test_an_override_that_may_end_actions_on_another_domain_is_approximate(tmp_path):
    # The lane change (lateral) starts at 3 s while the speed change from 1 s may run: esmini
    # ends the speed change where it is; the language cannot end it (W0802, translated).
    got = imported(tmp_path, speed("ramp", "override", 20, at(1)), lane_change("lc", "override", -2, at(3)))
    notes = priority_notes(got)
    assert got.plan is not None
    assert [(d.code, d.span.line) for d in notes] == [("W0802", 35)], notes  # the lane change's event
    assert "'lc' has priority override" in notes[0].message and "('ramp' may)" in notes[0].message
    assert "only those on a domain of its own actions (lat)" in notes[0].message


def test_a_lane_change_of_a_given_time_may_still_run_at_an_override_a_few_steps_after_it(tmp_path):
    # From 1 s over 2 s: it ends at 3 s, give or take a step; an override at 3.05 s may find it.
    got = imported(tmp_path, lane_change("lc", "override", -2, at(1), duration_s=2.0),
                   speed("ramp", "override", 20, at(3.05)))
    assert [d.code for d in priority_notes(got)] == ["W0802"] and "('lc' may)" in priority_notes(got)[0].message


def test_the_same_events_in_parallel_need_no_note(tmp_path):
    got = imported(tmp_path, speed("ramp", "overwrite", 20, at(1)), lane_change("lc", "parallel", -2, at(3)))
    assert got.plan is not None and not priority_notes(got), got.diagnostics


def test_a_skip_event_waits_until_no_other_event_of_its_maneuver_runs(tmp_path):
    got = imported(tmp_path, speed("ramp", "override", 20, at(1)), speed("low", "skip", 5, at(2), shape="step"))
    assert got.plan is not None and not priority_notes(got), got.diagnostics
    assert car_lines(got) == [
        "ramp: at 1 s behavior cruise speed 20 m/s duration 10 s shape linear max_accel 5 m/s^2 max_decel 10 m/s^2",
        "at 2 s when not (started(Car.ramp) and not ended(Car.ramp)) then behavior cruise speed 5 m/s shape step"]


def test_a_skip_event_on_an_edge_is_refused_unless_lenient(tmp_path):
    # esmini skips it at the one step its rising edge counts; `when rising (C and not running)`
    # would fire when the other ends: not the same, refused.
    events = (speed("ramp", "override", 20, at(1)), speed("low", "skip", 5, at(2, "rising"), shape="step"))
    got = imported(tmp_path, *events)
    assert got.plan is None
    assert [d.code for d in priority_notes(got)] == ["E0803"]
    assert "event 'low' has priority skip" in priority_notes(got)[0].message
    lenient = imported(tmp_path, *events, lenient=True)
    assert lenient.plan is not None and [d.code for d in priority_notes(lenient)] == ["W0801"]


def test_an_event_without_a_known_priority_is_refused(tmp_path):
    # esmini reads it as an undefined priority and never starts the event.
    for prio, said in (("", "no priority"), ("later", "priority 'later'")):
        got = imported(tmp_path, speed("ramp", prio, 20, at(1)))
        assert got.plan is None
        assert any(d.code == "E0803" and f"'ramp' has {said}: esmini never starts it" in d.message
                   for d in got.diagnostics), got.diagnostics


def test_an_event_started_on_anothers_start_finds_it_running(tmp_path):
    # The lane change starts as the speed change starts: the speed change's override cannot
    # find it running (it starts after), the lane change's may end the speed change (W0802).
    got = imported(tmp_path, speed("ramp", "override", 20, at(1)),
                   lane_change("lc", "override", -2, after("ramp", "startTransition")))
    notes = priority_notes(got)
    assert [d.code for d in notes] == ["W0802"]
    assert "event 'lc'" in notes[0].message and "('ramp' may)" in notes[0].message
