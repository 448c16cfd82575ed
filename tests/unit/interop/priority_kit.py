"""Small synthetic OpenSCENARIO files for event priorities (the structure of esmini's
cut-in_simple.xosc: a straight road, an ego and one car whose one maneuver holds the events)."""

from __future__ import annotations

import shutil

from addt_dsl.interop.openscenario.importer import import_xosc
from tests.conftest import ROOT

ESMINI = ROOT / "tests" / "data" / "esmini"

TEMPLATE = """<?xml version="1.0" encoding="UTF-8"?>
<OpenSCENARIO>
  <FileHeader revMajor="1" revMinor="2" date="2026-12-06T10:00:00" description="priority" author="addt"/>
  <CatalogLocations><VehicleCatalog><Directory path="../xosc/Catalogs/Vehicles"/></VehicleCatalog></CatalogLocations>
  <RoadNetwork><LogicFile filepath="../xodr/straight_500m.xodr"/></RoadNetwork>
  <Entities>
    <ScenarioObject name="Ego"><CatalogReference catalogName="VehicleCatalog" entryName="car_white"/></ScenarioObject>
    <ScenarioObject name="Car"><CatalogReference catalogName="VehicleCatalog" entryName="car_red"/></ScenarioObject>
  </Entities>
  <Storyboard>
    <Init><Actions>
      <Private entityRef="Ego">
        <PrivateAction><LongitudinalAction><SpeedAction>
          <SpeedActionDynamics dynamicsShape="step" dynamicsDimension="time" value="0"/>
          <SpeedActionTarget><AbsoluteTargetSpeed value="10"/></SpeedActionTarget>
        </SpeedAction></LongitudinalAction></PrivateAction>
        <PrivateAction><TeleportAction><Position>
          <LanePosition roadId="1" laneId="-1" offset="0" s="20"/></Position></TeleportAction></PrivateAction>
      </Private>
      <Private entityRef="Car">
        <PrivateAction><LongitudinalAction><SpeedAction>
          <SpeedActionDynamics dynamicsShape="step" dynamicsDimension="time" value="0"/>
          <SpeedActionTarget><AbsoluteTargetSpeed value="10"/></SpeedActionTarget>
        </SpeedAction></LongitudinalAction></PrivateAction>
        <PrivateAction><TeleportAction><Position>
          <LanePosition roadId="1" laneId="-1" offset="0" s="100"/></Position></TeleportAction></PrivateAction>
      </Private>
    </Actions></Init>
    <Story name="S">
      <Act name="A">
        <ManeuverGroup maximumExecutionCount="1" name="G">
          <Actors selectTriggeringEntities="false"><EntityRef entityRef="Car"/></Actors>
          <Maneuver name="M">
{events}
          </Maneuver>
        </ManeuverGroup>
        <StartTrigger><ConditionGroup><Condition name="go" delay="0" conditionEdge="none">
          <ByValueCondition><SimulationTimeCondition value="0" rule="greaterThan"/></ByValueCondition>
        </Condition></ConditionGroup></StartTrigger>
      </Act>
    </Story>
    <StopTrigger><ConditionGroup><Condition name="end" delay="0" conditionEdge="none">
      <ByValueCondition><SimulationTimeCondition value="{duration}" rule="greaterThan"/></ByValueCondition>
    </Condition></ConditionGroup></StopTrigger>
  </Storyboard>
</OpenSCENARIO>
"""


def at(time_s: float, edge: str = "none") -> str:
    """A start trigger: the simulation time past `time_s` [s]."""
    return (f'<StartTrigger><ConditionGroup><Condition name="t{time_s:g}" delay="0" conditionEdge="{edge}">'
            f'<ByValueCondition><SimulationTimeCondition value="{time_s:g}" rule="greaterThan"/></ByValueCondition>'
            "</Condition></ConditionGroup></StartTrigger>")


def after(event: str, state: str = "endTransition") -> str:
    """A start trigger: another event's state."""
    return ('<StartTrigger><ConditionGroup><Condition name="after" delay="0" conditionEdge="rising">'
            f'<ByValueCondition><StoryboardElementStateCondition storyboardElementType="event" '
            f'storyboardElementRef="{event}" state="{state}"/></ByValueCondition>'
            "</Condition></ConditionGroup></StartTrigger>")


def speed(name: str, priority: str, target: float, trigger: str, shape: str = "linear", dim: str = "time",
          value: float = 10.0) -> str:
    """An event of one SpeedAction to `target` [m/s]."""
    prio = f' priority="{priority}"' if priority else ""
    return (f'<Event name="{name}"{prio} maximumExecutionCount="1"><Action name="{name}_action"><PrivateAction>'
            f'<LongitudinalAction><SpeedAction><SpeedActionDynamics dynamicsShape="{shape}" '
            f'dynamicsDimension="{dim}" value="{value:g}"/><SpeedActionTarget><AbsoluteTargetSpeed '
            f'value="{target:g}"/></SpeedActionTarget></SpeedAction></LongitudinalAction></PrivateAction></Action>'
            f"{trigger}</Event>")


def lane_change(name: str, priority: str, lane: int, trigger: str, duration_s: float = 4.0) -> str:
    """An event of one LaneChangeAction to lane `lane` of the road, over `duration_s` [s]."""
    return (f'<Event name="{name}" priority="{priority}" maximumExecutionCount="1"><Action name="{name}_action">'
            '<PrivateAction><LateralAction><LaneChangeAction><LaneChangeActionDynamics dynamicsShape="sinusoidal" '
            f'value="{duration_s:g}" dynamicsDimension="time"/><LaneChangeTarget><AbsoluteTargetLane '
            f'value="{lane}"/></LaneChangeTarget></LaneChangeAction></LateralAction></PrivateAction></Action>'
            f"{trigger}</Event>")


def imported(tmp_path, *events: str, duration_s: float = 14.0, lenient: bool = False):
    """The import of a file whose car's maneuver holds `events`, beside esmini's road and catalogs."""
    if not (tmp_path / "xodr").exists():
        shutil.copytree(ESMINI / "xodr", tmp_path / "xodr")
        shutil.copytree(ESMINI / "xosc" / "Catalogs", tmp_path / "xosc" / "Catalogs")
    path = tmp_path / "xosc" / "p.xosc"
    path.write_text(TEMPLATE.format(events="\n".join(events), duration=f"{duration_s:g}"))
    return import_xosc(path, root=tmp_path, ego="scripted", lenient=lenient)
