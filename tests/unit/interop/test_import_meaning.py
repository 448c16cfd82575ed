"""Imported OpenSCENARIO does what the file says, as the standard defines it and esmini 3.6
executes it (its source: OSCPrivateAction.cpp, OSCCondition.cpp), nothing dropped silently."""

from __future__ import annotations

import re
import shutil

import numpy as np
import pytest

from addt_dsl.compiler import compile_source
from addt_dsl.interop.openscenario.importer import import_xosc
from addt_dsl.runtime.execute import execute
from addt_dsl.sweep import expand
from tests.conftest import ROOT

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
    1 m/s^2 change)."""
    path = _edited(tmp_path, "cut-in_simple.xosc", *((p, r.replace("DIM", "distance")) for p, r in NO_CHANGE))
    plan = _compiled(import_xosc(path, root=tmp_path / "esmini", ego="scripted"), tmp_path)
    (step,) = [t for t in plan.agents[0].triggers if t.label == "BrakeEvent"]
    assert step.clause.settings["shape"] == "step" and "accel" not in step.clause.settings
