"""A walker or cyclist that a CARLA ScenarioRunner file sets moving with a speed action (no route,
no trajectory) moves as ScenarioRunner moves it: along its body heading, in a straight line,
at the target speed from the step the action starts (srunner/scenariomanager/actorcontrols:
PedestrianControl, a walker's default controller, walks it along its forward vector at the
target speed; VehicleLongitudinalControl, CyclistCrossing's cyclist's, only opens the throttle,
no steering). Expected positions are read from the XML here (the Init WorldPosition, the
SpeedAction's target and the map's reference line), not from the importer or our export; a
CARLA file is in a left-handed frame: y and h are negated into the map's (OpenDRIVE) frame."""

from __future__ import annotations

import math
import warnings
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

CARLA = Path(__file__).resolve().parents[3] / "tests" / "data" / "carla"
TOL_M = 0.03


def _file_start(name: str, entity: str) -> tuple[float, float, float, float]:
    """(x, y, h, the first SpeedAction's target speed) of an entity, in the map's frame."""
    doc = ET.parse(CARLA / "xosc" / f"{name}.xosc").getroot()
    private = next(p for p in doc.iterfind("Storyboard/Init/Actions/Private") if p.get("entityRef") == entity)
    pos = private.find(".//TeleportAction/Position/WorldPosition")
    speed = next(a for a in doc.iterfind("Storyboard/Story//ManeuverGroup//Action")
                 if a.find("PrivateAction/LongitudinalAction/SpeedAction") is not None)
    v = float(speed.find(".//AbsoluteTargetSpeed").get("value"))
    return float(pos.get("x")), -float(pos.get("y")), -float(pos.get("h")), v


def _road_frame(road_id: str):
    """(s, t) of a map point on a road whose plan view is one line (Town01's are)."""
    doc = ET.parse(CARLA / "maps" / "Town01.xodr").getroot()
    road = next(r for r in doc.iter("road") if r.get("id") == road_id)
    (geo,) = road.iter("geometry")
    assert geo.find("line") is not None
    x0, y0, h = (float(geo.get(k)) for k in ("x", "y", "hdg"))
    return lambda x, y: ((x - x0) * math.cos(h) + (y - y0) * math.sin(h),
                         -(x - x0) * math.sin(h) + (y - y0) * math.cos(h))


def _run(name: str, duration_s: float):
    from addt_dsl.interop.openscenario.importer import import_xosc
    from addt_dsl.runtime.execute import execute
    from addt_dsl.sweep import expand

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        got = import_xosc(CARLA / "xosc" / f"{name}.xosc", maps=[CARLA / "maps"], lenient=True)
    plan = got.plan.model_copy(update={"duration_s": duration_s})
    trace = execute(expand(plan).specs[0]).trace
    return trace, trace.actors[got.entities["adversary"]]


def _last_standing(trace, actor, x0: float, y0: float) -> int:
    """The last row at which the actor is still at its start (the row before it moves)."""
    moved = next(i for i in range(len(trace.time)) if math.hypot(actor.x[i] - x0, actor.y[i] - y0) > 1e-9)
    return moved - 1


def test_cyclist_crossing_rides_across_the_road_along_its_heading():
    x0, y0, h, v = _file_start("CyclistCrossing", "adversary")
    trace, cyclist = _run("CyclistCrossing", 12.0)
    i0 = _last_standing(trace, cyclist, x0, y0)
    steps = round(1.0 / (trace.time[1] - trace.time[0]))
    off = {}
    for n in range(1, 6):
        i = i0 + n * steps
        assert i < len(trace.time), "the cyclist started too late for the check"
        want = (x0 + v * n * math.cos(h), y0 + v * n * math.sin(h))
        off[n] = round(math.hypot(cyclist.x[i] - want[0], cyclist.y[i] - want[1]), 4)
    assert all(d <= TOL_M for d in off.values()), off
    # Across road 21 (the road it starts beside), not along its sidewalk: from the sidewalk on
    # its left (t > 4.3 m: a 4 m lane and a 0.3 m shoulder) past its far shoulder, at one s.
    frame = _road_frame("21")
    s_start, t_start = frame(x0, y0)
    s_end, t_end = frame(cyclist.x[i0 + 5 * steps], cyclist.y[i0 + 5 * steps])
    assert t_start > 4.3 and t_end < -4.3, (t_start, t_end)
    assert abs(s_end - s_start) < TOL_M


def test_pedestrian_crossing_front_walks_out_across_the_ego_lane():
    """PedestrianCrossingFront's walker walks its 1.5 m at 10 m/s towards the ego's lane (the
    action's distance, ScenarioRunner's ChangeActorTargetSpeed) and stops there (the next event,
    started by that action's completion, sets 0 m/s)."""
    x0, y0, h, v = _file_start("PedestrianCrossingFront", "adversary")
    trace, walker = _run("PedestrianCrossingFront", 6.0)
    i0 = _last_standing(trace, walker, x0, y0)
    dt = trace.time[1] - trace.time[0]
    moved = [math.hypot(walker.x[i] - x0, walker.y[i] - y0) for i in range(len(trace.time))]
    # Along the heading at the target speed while it walks ...
    for i in range(i0 + 1, i0 + 1 + int(1.5 / (v * dt))):
        assert abs(walker.x[i] - (x0 + v * (i - i0) * dt * math.cos(h))) <= 1e-6
        assert abs(walker.y[i] - (y0 + v * (i - i0) * dt * math.sin(h))) <= 1e-6
    # ... then stopped 1.5 m out (one step of overshoot at most), in the map's -y: towards the
    # ego's lane on road 9, which runs along +x.
    assert 1.5 - 1e-9 <= moved[-1] <= 1.5 + v * dt + 1e-9
    assert walker.speed[-1] == 0.0
    s_start, t_start = _road_frame("9")(x0, y0)
    s_end, t_end = _road_frame("9")(walker.x[-1], walker.y[-1])
    assert t_end < t_start - 1.4 and abs(s_end - s_start) < 0.01
