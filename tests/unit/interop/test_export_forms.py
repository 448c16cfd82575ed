"""What the export writes for teleports, road ends, repeats, headways and accelerations, and
a condition it cannot write that reads a parameter (its text in the side file)."""

from __future__ import annotations

import json

from defusedxml import ElementTree as DET

from addt_dsl.compiler import compile_source
from addt_dsl.interop.xosc_export import export_run
from addt_dsl.sweep import expand

SOURCE = """
scenario forms {
  duration 5 s
  road r {
    line length 100 m
    lanes right 2
  }
  param lag = 1.5 s
  ego car on r lane -2 at 10 m speed 10 m/s {
    stack bev cruise_speed 10 m/s
  }
  agent a car on r lane -1 at 60 m speed 10 m/s at_road_end stop {
    back: when rising road_end(a) <= 0 m for 2 s repeat 3 then behavior teleport s 20 m t -1.75 m
    when gap(ego, a) < lag * speed(ego) then behavior cruise speed 5 m/s
    when accel(a) < -1 m/s^2 then behavior lane_change to -2 duration 3 s
    when distance(ego, a) > lag * speed(ego) then behavior brake decel 2 m/s^2
  }
}
"""


def exported(tmp_path):
    result = compile_source(SOURCE, "forms.addt")
    assert result.ok
    done = export_run(expand(result.plan).specs[0], tmp_path, "forms")
    return DET.parse(done.xosc_path).getroot(), json.loads(done.sidecar_path.read_text())


def test_teleport_road_end_and_repeat(tmp_path):
    root, _ = exported(tmp_path)
    event = next(e for e in root.iter("Event") if e.get("name") == "back")
    assert event.get("maximumExecutionCount") == "3"
    pos = event.find("Action/PrivateAction/TeleportAction/Position/RoadPosition")
    assert (pos.get("s"), pos.get("t"), pos.get("roadId")) == ("20.0", "-1.75", "1")
    cond = event.find("StartTrigger/ConditionGroup/Condition")
    assert cond.get("conditionEdge") == "rising" and float(cond.get("delay")) == 0.0
    assert cond.find("ByEntityCondition/EntityCondition/EndOfRoadCondition").get("duration") == "2.0"


def test_headway_and_acceleration_conditions(tmp_path):
    root, _ = exported(tmp_path)
    (headway,) = root.iter("TimeHeadwayCondition")
    assert (headway.get("entityRef"), headway.get("value"), headway.get("rule"), headway.get("freespace")) == \
        ("a", "1.5", "lessThan", "true")
    (accel,) = root.iter("AccelerationCondition")
    assert (accel.get("value"), accel.get("rule")) == ("-1.0", "lessThan")


def test_a_condition_without_a_form_that_reads_a_parameter_is_carried_with_its_text(tmp_path):
    _, side = exported(tmp_path)
    (cond,) = side["conditions"].values()
    assert cond["text"] == "distance(ego, a) > lag * speed(ego)"
