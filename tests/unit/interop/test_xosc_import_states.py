"""Storyboard element states in stop triggers: running states, states of actions, and of
events that translate to no step (esmini's pedestrian_collision.xosc)."""

from __future__ import annotations

import json
import re
import shutil

import pytest

from addt_dsl.compiler import compile_source
from addt_dsl.interop.openscenario.importer import import_xosc
from tests.conftest import ROOT

ESMINI = ROOT / "tests" / "data" / "esmini"

STOP_ON_STATE = """      <StopTrigger>
          <ConditionGroup>
              <Condition conditionEdge="%s" delay="4" name="AfterCutIn">
                  <ByValueCondition>
                      <StoryboardElementStateCondition storyboardElementType="%s"
                          storyboardElementRef="%s" state="%s"/>
                  </ByValueCondition>
              </Condition>
          </ConditionGroup>
      </StopTrigger>
   </Storyboard>"""


def _compiles(got, tmp_path):
    assert got.text is not None, [d.message for d in got.diagnostics]
    for name, body in got.side_files.items():
        (tmp_path / name).write_text(body)
    result = compile_source(got.text, "imported.addt", base_dir=tmp_path)
    assert result.ok, [d.message for d in result.diagnostics]
    return result.plan


def _cut_in_stopping_on(tmp_path, kind, ref, state, edge="none"):
    text = (ESMINI / "xosc" / "cut-in_simple.xosc").read_text()
    text = re.sub(r"      <StopTrigger>.*</Storyboard>", STOP_ON_STATE % (edge, kind, ref, state), text,
                  flags=re.S)
    shutil.copytree(ESMINI, tmp_path / "esmini")
    path = tmp_path / "esmini" / "xosc" / "stop.xosc"
    path.write_text(text)
    return import_xosc(path, root=tmp_path / "esmini")


@pytest.mark.parametrize("state,text", [
    ("runningState", "end when started(OverTaker.CutInEvent) and not ended(OverTaker.CutInEvent) delayed 4 s"),
    ("startTransition", "end when started(OverTaker.CutInEvent) delayed 4 s"),
    ("endTransition", "end when ended(OverTaker.CutInEvent) delayed 4 s")])
def test_a_stop_trigger_on_an_events_state(state, text, tmp_path):
    """runningState is started and not yet ended (it was refused)."""
    got = _cut_in_stopping_on(tmp_path, "event", "CutInEvent", state)
    assert text in (got.text or ""), [d.message for d in got.diagnostics]
    plan = _compiles(got, tmp_path)
    assert plan.end.delay_s.value == 4.0


def test_a_stop_trigger_on_an_actions_state_names_that_actions_step(tmp_path):
    got = _cut_in_stopping_on(tmp_path, "action", "BrakeAction", "completeState", "rising")
    assert "BrakeAction: when" in (got.text or ""), [d.message for d in got.diagnostics]
    assert "end when rising ended(OverTaker.BrakeAction) delayed 4 s" in got.text
    _compiles(got, tmp_path)


def test_a_stop_trigger_on_an_instant_event_is_on_the_state_that_starts_it(tmp_path):
    """pedestrian_collision.xosc: the run stops 3 s after 'raise_action' completes, a teleport
    that only raises the pedestrian (no step here); it happens 0.8 s after the pedestrian's
    'be_still_action' ended, so the run stops 3.8 s after that."""
    got = import_xosc(ESMINI / "xosc" / "pedestrian_collision.xosc", root=ESMINI, ego="scripted")
    plan = _compiles(got, tmp_path)
    assert "be_still_action: when" in got.text
    assert plan.end.delay_s.value == pytest.approx(3.8) and plan.end.edge == "rising"
    assert "ended(pedestrian_adult.be_still_action)" in json.dumps(plan.end.condition.model_dump())


def test_an_instant_event_started_otherwise_is_still_refused(tmp_path):
    text = (ESMINI / "xosc" / "pedestrian_collision.xosc").read_text()
    text = re.sub(r'<StoryboardElementStateCondition\s+storyboardElementType="action"\s+'
                  r'storyboardElementRef="be_still_action"\s+state="endTransition"\s*/>',
                  '<SimulationTimeCondition value="2" rule="greaterThan"/>', text, count=1)
    shutil.copytree(ESMINI, tmp_path / "esmini")
    path = tmp_path / "esmini" / "xosc" / "raise.xosc"
    path.write_text(text)
    got = import_xosc(path, root=tmp_path / "esmini", ego="scripted")
    assert got.text is None
    assert any("stop trigger on the action 'raise_action'" in d.message for d in got.diagnostics if d.is_error)


RUNNING_SOURCE = """scenario running {
  duration 20 s
  road r {
    line length 800 m
    lanes right 2 width 3.5 m
  }
  ego car on r lane -2 at 10 m speed 0 m/s
  agent a car on r lane -1 at 100 m speed 10 m/s {
    go: at 2 s behavior lane_change to -2 duration 3 s
  }
  end when %s delayed 1 s
}
"""


@pytest.mark.parametrize("formula,state", [("started(a.go) and not ended(a.go)", "runningState"),
                                           ("ended(a.go)", "endTransition")])
def test_a_stop_condition_on_a_steps_state_survives_export_and_import_without_the_side_file(formula, state,
                                                                                             tmp_path):
    """The storyboard's stop trigger names the step's event (it named `a.go`, which no event is)."""
    from addt_dsl.interop.xosc_export import export_run
    from addt_dsl.sweep import expand
    plan = compile_source(RUNNING_SOURCE % formula).plan
    done = export_run(expand(plan).specs[0], tmp_path)
    xml = done.xosc_path.read_text()
    assert f'storyboardElementRef="go" state="{state}"' in xml
    done.sidecar_path.unlink()
    back = import_xosc(done.xosc_path)
    assert back.plan is not None, [str(d) for d in back.diagnostics]
    assert back.plan.end.condition == plan.end.condition and back.plan.end.delay_s.value == 1.0


def test_a_stop_condition_without_an_openscenario_form_declares_its_parameter(tmp_path):
    """Its ParameterCondition's parameter is declared (it was not: the stop trigger was built
    after the declarations)."""
    from addt_dsl.interop.xosc_export import export_run
    from addt_dsl.sweep import expand
    plan = compile_source(RUNNING_SOURCE % "lat_gap(a, ego) > 1 m").plan
    xml = export_run(expand(plan).specs[0], tmp_path).xosc_path.read_text()
    assert '<ParameterCondition parameterRef="addt_condition_1"' in xml
    assert '<ParameterDeclaration name="addt_condition_1" parameterType="boolean"' in xml


def test_a_longitudinal_relative_distance_is_absolute_whichever_is_ahead():
    """two_plus_one_road.xosc: the Target, 15 m behind the Ego, overtakes it and cuts in once
    the distance exceeds 20 m again, now ahead (esmini compares |ds|; the distance was signed
    with the order at the start, so it never held)."""
    got = import_xosc(ESMINI / "xosc" / "two_plus_one_road.xosc", root=ESMINI, ego="scripted", lenient=True)
    assert "CutInEvent: when abs(gap(ego, Target) + 5.04 m) > 20 m then" in got.text


def _two_plus_one(tmp_path, old, new):
    text = (ESMINI / "xosc" / "two_plus_one_road.xosc").read_text()
    assert old in text
    shutil.copytree(ESMINI, tmp_path / "esmini")
    path = tmp_path / "esmini" / "xosc" / "clear.xosc"
    path.write_text(text.replace(old, new, 1))
    return import_xosc(path, root=tmp_path / "esmini", ego="scripted")


def test_a_relative_clearance_is_lane_ids_and_stations(tmp_path):
    """two_plus_one_road.xosc: the Target overtakes when the lane left of its own (+1) exists
    and no other actor is in it from 20 m behind to 40 m ahead (it was refused)."""
    got = import_xosc(ESMINI / "xosc" / "two_plus_one_road.xosc", root=ESMINI, ego="scripted")
    plan = _compiles(got, tmp_path)
    assert "not (lane_id(ego) - lane_id(Target) >= 1 and lane_id(ego) - lane_id(Target) <= 1 and lane_id(ego) * " \
           "lane_id(Target) > 0 and s(ego) - s(Target) >= -20 m and s(ego) - s(Target) <= 40 m)" in got.text
    # Lane -2 has a lane -1 beside it from s = 125 m to 375 m (two sections); lane -1 none.
    assert "lane_id(Target) == -2 and s(Target) >= 125 m and s(Target) < 175 m" in got.text
    assert "lane_id(Target) == -2 and s(Target) >= 325 m and s(Target) < 375 m" in got.text
    assert "lane_id(Target) == -1" not in got.text
    overtake = plan.agents[0].triggers[0]
    assert overtake.clause.name == "cruise" and overtake.edge is None


@pytest.mark.parametrize("old,new", [('freeSpace="false"', 'freeSpace="true"'),
                                     ('oppositeLanes="false"', 'oppositeLanes="true"'),
                                     ('<RelativeLaneRange from="1" to="1"/>', '')])
def test_a_clearance_not_translated_says_so(old, new, tmp_path):
    got = _two_plus_one(tmp_path, old, new)
    assert got.text is None
    assert any("a clearance in free space, over opposite lanes" in d.message for d in got.diagnostics if d.is_error)


def test_an_absolute_longitudinal_distance_survives_export_and_import_without_the_side_file(tmp_path):
    """`abs(gap(A, B) + H) OP D` (H half of both lengths: the import's form of esmini's
    longitudinal distance) goes out as that RelativeDistanceCondition and comes back."""
    from addt_dsl.interop.xosc_export import export_run
    from addt_dsl.sweep import expand
    source = RUNNING_SOURCE % "ended(a.go)"
    plan = compile_source(source).plan
    half = 0.5 * (plan.ego.length_m + plan.agents[0].length_m)
    source = source.replace("go: at 2 s", f"go: when abs(gap(a, ego) + {half:g} m) > 120 m")
    plan = compile_source(source).plan
    done = export_run(expand(plan).specs[0], tmp_path)
    xml = done.xosc_path.read_text()
    assert 'relativeDistanceType="longitudinal"' in xml and 'freespace="false"' in xml
    done.sidecar_path.unlink()
    back = import_xosc(done.xosc_path)
    assert back.plan is not None, [str(d) for d in back.diagnostics]
    assert back.plan.agents[0].triggers[0].condition == plan.agents[0].triggers[0].condition
