"""Imported OpenSCENARIO does what the file says, as the standard defines it and esmini 3.6
executes it (its source: OSCPrivateAction.cpp, OSCCondition.cpp), nothing dropped silently."""

from __future__ import annotations

import re
import shutil
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from addt_dsl.compiler import compile_file, compile_source
from addt_dsl.interop.openscenario.importer import import_xosc
from addt_dsl.interop.xosc_export import export_run
from addt_dsl.runtime.execute import execute
from addt_dsl.sweep import expand
from tests.conftest import ROOT
from tests.unit.interop.test_import_float_noise import CAR, CONTROLLER
from tests.unit.interop.test_xosc_import import SMALL

ESMINI = ROOT / "tests" / "data" / "esmini"


def _compiled(got, tmp_path):
    assert got.text is not None, [d.message for d in got.diagnostics]
    for name, body in got.side_files.items():
        (tmp_path / name).write_text(body)
    result = compile_source(got.text, "imported.addt", base_dir=tmp_path)
    assert result.ok, [d.message for d in result.diagnostics]
    return result.plan


def _edited(tmp_path, name: str, *edits: tuple[str, str]):
    """An esmini file with regex edits, in a copy of the esmini tree (its maps and catalogs)."""
    shutil.copytree(ESMINI, tmp_path / "esmini")
    text = (ESMINI / "xosc" / name).read_text()
    for pattern, repl in edits:
        text, n = re.subn(pattern, repl, text, flags=re.S)
        assert n == 1, pattern
    path = tmp_path / "esmini" / "xosc" / "edited.xosc"
    path.write_text(text)
    return path


# cut-in_simple.xosc's OverTaker (25 m/s from Init) gets a linear change over 3 s to the speed
# it has, at 2 s, and the run stops when that event ends.
NO_CHANGE = (
    (r'<SpeedActionDynamics dynamicsShape="linear" value="-5" dynamicsDimension="rate"/>\s*'
     r'<SpeedActionTarget>\s*<AbsoluteTargetSpeed value="0"/>',
     '<SpeedActionDynamics dynamicsShape="linear" value="3" dynamicsDimension="DIM"/>'
     '<SpeedActionTarget><AbsoluteTargetSpeed value="25"/>'),
    (r'(<Condition name="BrakeCondition".*?)<ByEntityCondition>.*?</ByEntityCondition>',
     r'\1<ByValueCondition><SimulationTimeCondition value="2" rule="greaterThan"/></ByValueCondition>'),
    (r'<StopTrigger>\s*<ConditionGroup>.*</StopTrigger>',
     '<StopTrigger><ConditionGroup><Condition name="e" delay="0" conditionEdge="none"><ByValueCondition>'
     '<StoryboardElementStateCondition storyboardElementType="event" storyboardElementRef="BrakeEvent" '
     'state="endTransition"/></ByValueCondition></Condition></ConditionGroup></StopTrigger>'),
)


def test_a_speed_change_over_a_time_without_a_difference_takes_that_time(tmp_path):
    """OpenSCENARIO: a SpeedAction over a time T runs for T and completes. With no speed
    difference esmini's TransitionDynamics still steps its parameter from 0 to T (the speed
    stays) and ends the action then: the event ends 3 s after it starts (it was read as a
    1 m/s^2 change, complete at once)."""
    path = _edited(tmp_path, "cut-in_simple.xosc", *((p, r.replace("DIM", "time")) for p, r in NO_CHANGE))
    got = import_xosc(path, root=tmp_path / "esmini", ego="scripted")
    plan = _compiled(got, tmp_path)
    (step,) = [t for t in plan.agents[0].triggers if t.label == "BrakeEvent"]
    assert step.clause.name == "cruise" and step.clause.settings["duration"].value == 3.0
    trace = execute(expand(plan).specs[0]).trace
    state, t = trace.steps["OverTaker.BrakeEvent"], trace.time
    started, ended = t[np.argmax(state >= 1)], t[np.argmax(state >= 2)]
    assert started == pytest.approx(2.0, abs=0.02)
    assert ended - started == pytest.approx(3.0, abs=0.02)
    assert trace.duration_s == pytest.approx(ended, abs=0.02)  # the stop trigger waits for it
    speed = np.hypot(np.diff(trace.actors["OverTaker"].x), np.diff(trace.actors["OverTaker"].y)) / trace.period_s
    assert np.allclose(speed[t[1:] > started + 0.1], 25.0, atol=0.05)  # unchanged


def test_a_speed_change_over_a_distance_without_a_difference_is_at_once(tmp_path):
    """esmini converts a distance to a time, 0 where the speeds are equal: a step (it was a
    1 m/s^2 change); the event ends a step after it starts."""
    path = _edited(tmp_path, "cut-in_simple.xosc", *((p, r.replace("DIM", "distance")) for p, r in NO_CHANGE))
    plan = _compiled(import_xosc(path, root=tmp_path / "esmini", ego="scripted"), tmp_path)
    (step,) = [t for t in plan.agents[0].triggers if t.label == "BrakeEvent"]
    assert step.clause.settings["distance"].value == 3.0 and "accel" not in step.clause.settings
    trace = execute(expand(plan).specs[0]).trace
    state, t = trace.steps["OverTaker.BrakeEvent"], trace.time
    started, ended = t[np.argmax(state >= 1)], t[np.argmax(state >= 2)]
    assert started == pytest.approx(2.0, abs=0.02) and ended - started <= trace.period_s + 1e-9
    speed = np.hypot(np.diff(trace.actors["OverTaker"].x), np.diff(trace.actors["OverTaker"].y)) / trace.period_s
    assert np.allclose(speed, 25.0, atol=0.05)


def test_a_standing_ego_under_the_stack_stands_when_the_file_keeps_it_standing(tmp_path):
    """`--ego stack`: the stack cruises at the speed the file gives its ego; an ego that
    starts at 0 m/s and that nothing sets going (and no speed limit on the map) gets
    `cruise_speed 0 m/s` and stands, as under OpenSCENARIO's default controller (it had no
    stack line: the stack's default 25 m/s drove it off)."""
    path = _edited(tmp_path, "cut-in_simple.xosc",
                   (r'(<Private entityRef="Ego">.*?<AbsoluteTargetSpeed value=)"20"', r'\1"0"'),
                   (r'<StopTrigger>\s*<ConditionGroup>.*</StopTrigger>',
                    '<StopTrigger><ConditionGroup><Condition name="e" delay="0" conditionEdge="none">'
                    '<ByValueCondition><SimulationTimeCondition value="3" rule="greaterThan"/></ByValueCondition>'
                    '</Condition></ConditionGroup></StopTrigger>'))
    got = import_xosc(path, root=tmp_path / "esmini")
    assert "stack bev cruise_speed 0 m/s" in (got.text or ""), [d.message for d in got.diagnostics]
    assert any(d.code == "W0802" and "nothing in the file sets it going" in d.message for d in got.diagnostics)
    trace = execute(expand(_compiled(got, tmp_path)).specs[0]).trace
    ego = trace.actors["ego"]
    assert trace.duration_s >= 2.9
    assert np.hypot(ego.x[-1] - ego.x[0], ego.y[-1] - ego.y[0]) < 0.05


@pytest.mark.parametrize("name,speed,label", [("follow_ghost", 100 / 3.6, "<AbsoluteTargetSpeed>"),
                                               ("speed-profile", 10.0, "<SpeedProfileEntry>")])
def test_a_standing_ego_set_going_by_the_file_cruises_at_the_first_speed_asked(name, speed, label):
    """follow_ghost.xosc starts its Ego at 0 m/s and sets it going at 100/3.6 m/s when the
    story starts (speed-profile.xosc: a profile whose first speed above 0 is 10 m/s): under
    the stack, that cruise speed (W0802 at that element), not the stack's default."""
    got = import_xosc(ESMINI / "xosc" / f"{name}.xosc", root=ESMINI, lenient=True)
    assert got.plan is not None, [d.message for d in got.diagnostics]
    stack = got.plan.ego.stack
    assert stack is not None and stack.settings["cruise_speed"].value == pytest.approx(speed)
    note = next(d for d in got.diagnostics if "the file's actions set it going" in d.message)
    assert note.code == "W0802" and note.label == label and note.span.line == 88


def test_a_distance_to_a_point_survives_export_and_import_without_the_side_file(tmp_path):
    """The import's form of ReachPositionCondition (the Euclidean distance of the entity's
    reference point to the position's point, below the tolerance) exports as a
    DistanceCondition to a WorldPosition (OpenSCENARIO 1.2 deprecates ReachPositionCondition
    for it; it was a ParameterCondition that only the side file explained) and imports back
    as the same condition."""
    plan = compile_file(ROOT / "tests" / "data" / "interop" / "every_position.addt").plan
    done = export_run(expand(plan).specs[0], tmp_path / "x", "scenario")
    (cond,) = ET.parse(done.xosc_path).getroot().iter("DistanceCondition")
    assert (cond.get("value"), cond.get("rule"), cond.get("freespace"), cond.get("relativeDistanceType")) == \
        ("2.0", "lessThan", "false", "euclidianDistance")
    assert cond.find("Position/WorldPosition").attrib == {"x": "120.0", "y": "-5.25"}
    assert not list(ET.parse(done.xosc_path).getroot().iter("ParameterCondition"))
    done.sidecar_path.unlink()
    got = import_xosc(done.xosc_path)
    back = next(a for a in got.plan.agents if a.name == "late").triggers[0].condition
    assert back == next(a for a in plan.agents if a.name == "late").triggers[0].condition


def test_a_reach_position_orientation_is_said_not_dropped(tmp_path):
    """esmini's ReachPositionCondition with an Orientation in its position also requires the
    entity's heading, pitch and roll within 0.05 rad (TrigByReachPosition): the translation
    checks the distance alone, and says so (it said nothing)."""
    path = _edited(tmp_path, "pedestrian.xosc",
                   (r'<LanePosition roadId="0" laneId="-3" s="0"/>',
                    '<LanePosition roadId="0" laneId="-3" s="0"><Orientation type="relative" h="0"/></LanePosition>'))
    got = import_xosc(path, root=tmp_path / "esmini")
    note = next(d for d in got.diagnostics if "the position's Orientation" in d.message)
    assert note.code == "W0802" and note.label == "<Orientation>" and note.span.line == 260
    assert got.plan is not None and got.plan.end is not None


@pytest.mark.parametrize("controller,speed", [(False, 0.0), (True, 50 / 3.6)])
def test_a_speed_limit_drives_a_standing_ego_only_when_the_file_gives_it_a_controller(controller, speed, tmp_path):
    """A standing ego on OpenSCENARIO's default controller stays standing whatever the map's
    limit; one the file gives a controller (ScenarioRunner's external agent) is the stack's
    to drive, at the limit."""
    xodr = (ESMINI / "xodr" / "straight_500m.xodr").read_text()
    head = '<road name="" length="5.0000000000000000e+02" id="1" junction="-1">'
    (tmp_path / "r.xodr").write_text(xodr.replace(head, head + '<type s="0" type="town"><speed max="50" '
                                                              'unit="km/h"/></type>'))
    (tmp_path / "s.xosc").write_text(SMALL.replace("ENTITY", CAR + (CONTROLLER if controller else "")))
    got = import_xosc(tmp_path / "s.xosc", lenient=True)
    assert got.plan is not None, [d.message for d in got.diagnostics]
    assert got.plan.ego.stack.settings["cruise_speed"].value == pytest.approx(speed)


# cut-in_simple.xosc's OverTaker (25 m/s from Init): its first event (in the file) steps it to
# 10 m/s when the time passes 30 s (never, in this run); its second changes it linearly over 4 s
# to 15 m/s when the time passes 1 s, and the run stops when that event ends.
GUESS_MISSED = (
    (r'<LateralAction>\s*<LaneChangeAction >.*?</LateralAction>',
     '<LongitudinalAction><SpeedAction><SpeedActionDynamics dynamicsShape="step" dynamicsDimension="time" '
     'value="0"/><SpeedActionTarget><AbsoluteTargetSpeed value="10"/></SpeedActionTarget></SpeedAction>'
     '</LongitudinalAction>'),
    (r'(<Condition name="CutInStartCondition".*?)<ByEntityCondition>.*?</ByEntityCondition>',
     r'\1<ByValueCondition><SimulationTimeCondition value="30" rule="greaterThan"/></ByValueCondition>'),
    (NO_CHANGE[0][0], NO_CHANGE[0][1].replace('value="3" dynamicsDimension="DIM"', 'value="4" dynamicsDimension="time"')
     .replace('value="25"', 'value="15"')),
    (NO_CHANGE[1][0], NO_CHANGE[1][1].replace('value="2"', 'value="1"')),
    NO_CHANGE[2],
)


def test_a_linear_speed_change_over_a_time_starts_from_the_speed_the_entity_has(tmp_path):
    """OpenSCENARIO: a linear SpeedAction over a time T goes from the speed the entity has when
    it starts (esmini's LongSpeedAction::Start) to the target in T. The importer's guess of
    that speed, 10 m/s from the event before it in the file, is wrong here (that event has
    not run): 25 m/s to 15 m/s in 4 s, 2.5 m/s^2 (it was read as a 1.25 m/s^2 change, from
    the guessed 10 m/s, and took 8 s)."""
    path = _edited(tmp_path, "cut-in_simple.xosc", *GUESS_MISSED)
    got = import_xosc(path, root=tmp_path / "esmini", ego="scripted")
    trace = execute(expand(_compiled(got, tmp_path)).specs[0]).trace
    state, t = trace.steps["OverTaker.BrakeEvent"], trace.time
    started, ended = t[np.argmax(state >= 1)], t[np.argmax(state >= 2)]
    assert started == pytest.approx(1.0, abs=0.02)
    assert ended - started == pytest.approx(4.0, abs=0.02)
    over = trace.actors["OverTaker"]
    speed = np.hypot(np.diff(over.x), np.diff(over.y)) / trace.period_s  # over each step
    mid = 0.5 * (t[1:] + t[:-1])
    # Linear from 25 m/s to 15 m/s over exactly 4 s from the start (hand-computed).
    expected = np.where(mid < started, 25.0, np.maximum(25.0 - 2.5 * (mid - started), 15.0))
    assert np.max(np.abs(speed - expected)) < 0.1


def test_a_relative_speed_change_over_a_time_is_stretched_to_the_performance(tmp_path):
    """esmini stretches a speed change over a time whose rate exceeds the vehicle's
    Performance (TransitionDynamics::SetMaxRate), relative targets too: 25 m/s to the Ego's
    20 m/s - 5 m/s in 1 s would take 10 m/s^2; with maxDeceleration 2 m/s^2 it takes 5 s
    (it took 1 s), and the translation says where it differs from esmini (W0802)."""
    path = _edited(tmp_path, "cut-in_simple.xosc",
                   (r'entryName="\$TargetVehicle"/>',
                    r'entryName="$TargetVehicle"><ParameterAssignments><ParameterAssignment '
                    r'parameterRef="MaxDeceleration" value="2"/></ParameterAssignments></CatalogReference>'),
                   (NO_CHANGE[0][0], '<SpeedActionDynamics dynamicsShape="linear" value="1" dynamicsDimension="time"/>'
                    '<SpeedActionTarget><RelativeTargetSpeed entityRef="Ego" value="-5" '
                    'speedTargetValueType="delta" continuous="true"/>'),
                   (NO_CHANGE[1][0], NO_CHANGE[1][1].replace('value="2"', 'value="1"')),
                   (r'<StopTrigger>\s*<ConditionGroup>.*</StopTrigger>',
                    '<StopTrigger><ConditionGroup><Condition name="e" delay="0" conditionEdge="none">'
                    '<ByValueCondition><SimulationTimeCondition value="8" rule="greaterThan"/></ByValueCondition>'
                    '</Condition></ConditionGroup></StopTrigger>'))
    got = import_xosc(path, root=tmp_path / "esmini", ego="scripted")
    assert any(d.code == "W0802" and "a relative target over a time" in d.message for d in got.diagnostics)
    trace = execute(expand(_compiled(got, tmp_path)).specs[0]).trace
    t = trace.time
    over = trace.actors["OverTaker"]
    speed = np.hypot(np.diff(over.x), np.diff(over.y)) / trace.period_s
    started = t[np.argmax(speed < 25.0 - 1e-6)]  # the step it starts in: the condition's, t > 1 s
    assert started == pytest.approx(1.0, abs=0.02)
    mid = 0.5 * (t[1:] + t[:-1])
    expected = np.where(mid < started, 25.0, np.maximum(25.0 - 2.0 * (mid - started), 15.0))  # by hand
    assert np.max(np.abs(speed - expected)) < 0.1


def _guess_missed(target: float, dynamics: str, guess: float = 10.0) -> tuple:
    """GUESS_MISSED with the second event's target and dynamics (attributes), the first's
    (never run) step to `guess`."""
    change = (NO_CHANGE[0][0], '<SpeedActionDynamics dynamicsShape="linear" ' + dynamics + '/>'
              f'<SpeedActionTarget><AbsoluteTargetSpeed value="{target:g}"/>')
    return ((GUESS_MISSED[0][0], GUESS_MISSED[0][1].replace('value="10"', f'value="{guess:g}"')),
            GUESS_MISSED[1], change, *GUESS_MISSED[3:])


def _speed_from(tmp_path, edits, event: str = "OverTaker.BrakeEvent"):
    """The OverTaker's speed over each step [m/s], the steps' mid times, and when the event
    started and ended [s]."""
    path = _edited(tmp_path, "cut-in_simple.xosc", *edits)
    got = import_xosc(path, root=tmp_path / "esmini", ego="scripted")
    trace = execute(expand(_compiled(got, tmp_path)).specs[0]).trace
    state, t = trace.steps[event], trace.time
    over = trace.actors["OverTaker"]
    speed = np.hypot(np.diff(over.x), np.diff(over.y)) / trace.period_s
    return speed, 0.5 * (t[1:] + t[:-1]), t[np.argmax(state >= 1)], t[np.argmax(state >= 2)]


def test_a_speed_change_at_a_rate_goes_toward_the_target_from_the_speed_the_entity_has(tmp_path):
    """OpenSCENARIO: a SpeedAction at a rate changes the speed toward the target at that rate
    whichever way it is from the speed the entity has when it starts (esmini's
    LongSpeedAction::Start signs the rate then), the peak within the Performance
    (maxAcceleration 5 m/s^2 here: 8 m/s^2 is cut to it). The importer's guess, 40 m/s from the
    event before it in the file (never run), is above the 30 m/s target; the entity is at
    25 m/s: it speeds up at 5 m/s^2 for 1 s (it was read as braking to 30 m/s and never moved)."""
    speed, mid, started, ended = _speed_from(
        tmp_path, _guess_missed(30.0, 'value="8" dynamicsDimension="rate"', guess=40.0))
    assert started == pytest.approx(1.0, abs=0.02)
    assert ended - started == pytest.approx(1.0, abs=0.03)
    expected = np.where(mid < started, 25.0, np.minimum(25.0 + 5.0 * (mid - started), 30.0))  # hand-computed
    assert np.max(np.abs(speed - expected)) < 0.1


def test_a_speed_change_over_a_distance_takes_its_time_from_the_speed_the_entity_has(tmp_path):
    """OpenSCENARIO: a SpeedAction over a distance d from v0 (the speed when it starts) to v1
    takes 2 d / (v0 + v1) (esmini's LongSpeedAction::Start): 60 m from 25 m/s to 15 m/s is
    3 s at 10/3 m/s^2. The importer's guess, 10 m/s, is below the target (it was read as a
    speed-up at (15^2 - 10^2) / 120 = 1.04 m/s^2, and took 9.6 s)."""
    speed, mid, started, ended = _speed_from(tmp_path, _guess_missed(15.0, 'value="60" dynamicsDimension="distance"'))
    assert started == pytest.approx(1.0, abs=0.02)
    assert ended - started == pytest.approx(3.0, abs=0.03)
    expected = np.where(mid < started, 25.0, np.maximum(25.0 - 10.0 / 3.0 * (mid - started), 15.0))  # hand-computed
    assert np.max(np.abs(speed - expected)) < 0.1
    over = np.sum(speed[(mid > started) & (mid < ended)]) * (mid[1] - mid[0])
    assert over == pytest.approx(60.0, abs=0.5)  # the distance it takes
