"""Every imported entity starts facing where its file says: for each corpus file (esmini's 27 and
CARLA ScenarioRunner's examples), each entity's heading at t = 0 in the trace equals the heading
of its Init TeleportAction position (else of the first vertex of its Init trajectory), read from
the XML here (not from the importer, not from our export), within 1e-6 rad modulo 2 pi (where
the heading is a lane's, plus the twin's sampling of the reference line, `sampling_bound`: 0 on
lines and arcs), the ego driven by the stack and scripted.

The heading a position gives, as OpenSCENARIO 1.2 defines it and esmini 3.6 places it
(OSCPosition.cpp, RoadManager.cpp `Position::SetRelativePosition`), in the OpenDRIVE frame
(radians, counter-clockwise from +x):
- WorldPosition: `h` (absolute);
- LanePosition: an absolute Orientation's `h`; else the lane's driving direction (the road's
  reference heading at s, plus pi on a lane driven against s) plus a relative Orientation's `h`;
- RoadPosition, RelativeRoadPosition: an absolute Orientation's `h`; else the road's reference
  heading at s (+s, whatever the lane) plus a relative `h`;
- RelativeLanePosition: as a LanePosition, at the referred entity's s + ds;
- RoutePosition (from lane coordinates on a catalog route, on its first road): the driving
  direction of the first waypoint's lane.
A file whose description starts with 'CARLA:' is in CARLA's left-handed frame: y, t, offsets and
headings are negated into OpenDRIVE's (as ScenarioRunner reads it)."""

from __future__ import annotations

import ast
import csv
import gzip
import math
import operator
import re
import warnings
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from addt_dsl.road.xodr import load_xodr
from addt_dsl.runtime.fastroad import STEP_M

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[3]
ESMINI = ROOT / "tests" / "data" / "esmini"
CARLA = ROOT / "tests" / "data" / "carla"
REF = ROOT / "tests" / "data" / "esmini-ref"
TOL_RAD = 1e-6
FILES = [p for p in sorted((ESMINI / "xosc").glob("*.xosc")) + sorted((CARLA / "xosc").glob("*.xosc"))
         if ET.parse(p).getroot().find("Storyboard") is not None]  # not the catalogs

_OPS = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul, ast.Div: operator.truediv,
        ast.USub: operator.neg, ast.UAdd: operator.pos}


def _arith(node) -> float:
    if isinstance(node, ast.Expression):
        return _arith(node.body)
    if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)):
        return float(node.value)
    if isinstance(node, ast.BinOp) and type(node.op) in _OPS:
        return _OPS[type(node.op)](_arith(node.left), _arith(node.right))
    if isinstance(node, ast.UnaryOp) and type(node.op) in _OPS:
        return _OPS[type(node.op)](_arith(node.operand))
    raise ValueError(f"not an arithmetic expression: {ast.dump(node)}")


class Doc:
    """One corpus file as the standard reads it: its parameters, its map, its frame."""

    def __init__(self, path: Path):
        self.path = path
        self.root = ET.parse(path).getroot()
        self.params = {d.get("name"): d.get("value") for d in self.root.iterfind("ParameterDeclarations/"
                                                                                 "ParameterDeclaration")}
        header = self.root.find("FileHeader")
        self.carla = header is not None and (header.get("description") or "").startswith("CARLA:")
        logic = self.root.find("RoadNetwork/LogicFile")
        if logic is None:  # world positions only
            self.network = None
            return
        name = logic.get("filepath")
        self.network = load_xodr(CARLA / "maps" / f"{name}.xodr" if self.carla else (path.parent / name).resolve())

    def num(self, el, attr: str, default: float | None = None) -> float:
        raw = el.get(attr)
        if raw is None:
            if default is None:
                raise KeyError(attr)
            return default
        return self.value(raw)

    def value(self, raw: str) -> float:
        """A number, a `$parameter` or a `${expression}` (parameters declared with either)."""
        raw = raw.strip()
        if raw.startswith("${") and raw.endswith("}"):
            body = re.sub(r"\$(\w+)", lambda m: repr(self.value(self.params[m.group(1)])), raw[2:-1])
            return _arith(ast.parse(body, mode="eval"))
        if raw.startswith("$"):
            return self.value(self.params[raw[1:]])
        return float(raw)

    def lateral(self, value: float) -> float:
        """y, t, an offset or a heading in OpenDRIVE's frame."""
        return -value if self.carla else value


def _road_heading(doc: Doc, road_id: str, s: float) -> float:
    return float(doc.network.road(road_id).reference_pose(s)[2])


def sampling_bound(doc: Doc, road_id: str, s: float) -> float:
    """How far [rad] the twin's heading may stand off a road's exact reference heading at s:
    it samples the reference line every STEP_M and interpolates the heading linearly
    (addt_dsl/runtime/fastroad.py), off by at most |dκ/ds| STEP_M² / 8 (0 on lines and arcs)."""
    road = doc.network.road(road_id)
    a, b = max(s - STEP_M, 0.0), min(s + STEP_M, road.length)
    rate = abs(float(road.curvature(b)) - float(road.curvature(a))) / (b - a) if b > a else 0.0
    return rate * STEP_M ** 2 / 8.0


def route_start(doc: Doc, pos) -> tuple[str, float, int] | None:
    """(road, s, the way the route runs along s) of a RoutePosition from lane coordinates on
    a catalog route, where its pathS stays on the route's first road (None elsewhere): the
    route runs from its first waypoint in that waypoint's lane's driving direction."""
    ref = pos.find("RouteRef/CatalogReference")
    coords = pos.find("InRoutePosition/FromLaneCoordinates")
    if ref is None or coords is None:
        return None
    folder = doc.root.find("CatalogLocations/RouteCatalog/Directory").get("path")
    catalog = ET.parse((doc.path.parent / folder / f"{ref.get('catalogName')}.xosc").resolve()).getroot()
    route = catalog.find(f"Catalog/Route[@name='{ref.get('entryName')}']")
    first = route.find("Waypoint/Position/LanePosition")
    road = doc.network.road(first.get("roadId"))
    way = road.travel_direction(int(doc.num(first, "laneId")))
    s = doc.num(first, "s") + way * doc.num(coords, "pathS")
    return (first.get("roadId"), s, way) if 0.0 <= s <= road.length else None


def expected_headings(doc: Doc) -> dict[str, tuple[float, float]]:
    """The heading [rad] each entity's Init TeleportAction gives it (the entities the file
    places by a position this module reads), with the tolerance it is checked to [rad]:
    TOL_RAD, plus the twin's sampling of the reference line where the heading is the lane's."""
    out: dict[str, tuple[float, float]] = {}
    where: dict[str, tuple[str, float, int | None]] = {}  # entity -> (road, s, lane) of road positions
    for private in doc.root.iterfind("Storyboard/Init/Actions/Private"):
        who = private.get("entityRef")
        pos = private.find("PrivateAction/TeleportAction/Position/*")
        if pos is None:  # no TeleportAction: a trajectory's first vertex (esmini starts it there)
            pos = private.find("PrivateAction/RoutingAction/FollowTrajectoryAction//Polyline/Vertex/Position/*")
        if pos is None:
            continue
        orient = pos.find("Orientation")
        rel_h = doc.lateral(doc.num(orient, "h", 0.0)) if orient is not None else 0.0
        absolute = orient is not None and orient.get("type") == "absolute" and orient.get("h") is not None
        if pos.tag == "WorldPosition":
            if pos.get("h") is not None:
                out[who] = doc.lateral(doc.num(pos, "h")), TOL_RAD
            continue
        if pos.tag == "RoutePosition":
            got = route_start(doc, pos)
            if got is not None:
                road, s, way = got
                out[who] = _road_heading(doc, road, s) + (math.pi if way < 0 else 0.0), \
                    TOL_RAD + sampling_bound(doc, road, s)
            continue
        if pos.tag in ("LanePosition", "RoadPosition"):
            road, s = pos.get("roadId"), doc.num(pos, "s")
            lane = int(doc.num(pos, "laneId")) if pos.tag == "LanePosition" else None
        elif pos.tag in ("RelativeRoadPosition", "RelativeLanePosition") and pos.get("entityRef") in where:
            road, s_ref, lane_ref = where[pos.get("entityRef")]
            s = s_ref + doc.num(pos, "ds", 0.0)
            lane = None
            if pos.tag == "RelativeLanePosition":
                if lane_ref is None:
                    continue
                d_lane = int(doc.num(pos, "dLane"))
                lane = lane_ref + d_lane
                if lane * lane_ref <= 0 and d_lane:
                    lane += 1 if d_lane > 0 else -1
        else:
            continue
        where[who] = (road, s, lane)
        if absolute:
            out[who] = rel_h, TOL_RAD
            continue
        odr = doc.network.road(road)
        s = min(max(s, 0.0), odr.length)
        base = _road_heading(doc, road, s)
        if lane is not None and lane != 0 and odr.travel_direction(lane) < 0:
            base += math.pi
        out[who] = base + rel_h, TOL_RAD + sampling_bound(doc, road, s)
    return out


def esmini_initial_headings(path: Path) -> dict[str, float]:
    """esmini 3.6's headings at t = 0 by entity (its reference trajectory, run as-is or without
    controllers), {} without one."""
    with open(REF / "INDEX.csv", newline="") as fh:
        rows = [r for r in csv.DictReader(fh) if r["file"] and r["xosc"] == path.name]
    if not rows:
        return {}
    out: dict[str, float] = {}
    with gzip.open(REF / rows[0]["file"], "rt", newline="") as fh:
        for row in csv.DictReader(fh):
            if float(row["time"]) > 0.0:
                break
            out[row["entity"]] = float(row["heading"])
    return out


def angle_error(a: float, b: float) -> float:
    return abs(math.remainder(a - b, 2.0 * math.pi))


def _import(path: Path, ego: str):
    from addt_dsl.interop.openscenario.importer import import_xosc

    carla = path.is_relative_to(CARLA)
    kw = {"maps": [CARLA / "maps"]} if carla else {"root": ESMINI}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return import_xosc(path, lenient=True, ego=ego, **kw)


def initial_headings_in_trace(path: Path, ego: str = "stack") -> dict[str, float]:
    """Each imported entity's heading [rad] in the trace's first row (t = 0)."""
    from addt_dsl.runtime.execute import execute
    from addt_dsl.sweep import expand

    got = _import(path, ego)
    assert got.plan is not None, [d.message for d in got.diagnostics if d.is_error]
    plan = got.plan.model_copy(update={"duration_s": 0.02})
    trace = execute(expand(plan).specs[0]).trace
    assert trace.time[0] == 0.0
    return {entity: float(trace.actors[actor].heading[0]) for entity, actor in got.entities.items()}


def heading_differences(path: Path, ego: str = "stack") -> dict[str, tuple[float, float]]:
    """entity -> (file's heading, trace's heading) [rad] where they differ by more than the
    tolerance `expected_headings` gives."""
    doc = Doc(path)
    want = expected_headings(doc)
    got = initial_headings_in_trace(path, ego)
    missing = set(want) - set(got)
    assert not missing, f"entities not imported: {sorted(missing)}"
    return {who: (round(h, 7), round(got[who], 7)) for who, (h, tol) in sorted(want.items())
            if angle_error(h, got[who]) > tol}


# Files without a road network are refused (the language places actors on roads): not here.
ON_ROADS = [p for p in FILES if Doc(p).network is not None]


@pytest.mark.parametrize("ego", ["stack", "scripted"])
@pytest.mark.parametrize("path", ON_ROADS, ids=lambda p: f"{p.parent.parent.name}/{p.stem}")
def test_every_entity_starts_facing_where_its_file_says(path, ego):
    assert heading_differences(path, ego) == {}


def test_only_parking_lot_has_no_road_network():
    assert [p.stem for p in FILES if p not in ON_ROADS] == ["parking_lot"]


@pytest.mark.parametrize("path", [p for p in FILES if p.is_relative_to(ESMINI)], ids=lambda p: p.stem)
def test_the_files_headings_as_read_here_are_esminis(path):
    """The reading above is esmini's: its heading at t = 0 for every entity this module reads
    (to esmini's five decimals)."""
    ref = esmini_initial_headings(path)
    if not ref:
        pytest.skip("no esmini reference trajectory")
    want = expected_headings(Doc(path))
    assert want, "no entity read"
    assert {w: (round(h, 5), ref[w]) for w, (h, _) in want.items() if w in ref and angle_error(h, ref[w]) > 1e-5} == {}


def test_slaloms_containers_are_turned_for_collisions_sensors_and_osi():
    """The heading in the trace is the one the twin's bodies have: the box table that
    collisions and lidar rays meet, and the ground truth an OSI view and perception report
    (CARLA's Slalom: c1 +pi/2, c2 -pi/2, c3-c5 0 in the map's frame)."""
    from addt_dsl.runtime import phases
    from addt_dsl.runtime.agents import Fleets
    from addt_dsl.runtime.state import RunState
    from addt_dsl.sweep import expand

    path = CARLA / "xosc" / "Slalom.xosc"
    want = {w: h for w, (h, _) in expected_headings(Doc(path)).items() if w.startswith("c")}
    run = RunState(expand(_import(path, "stack").plan).specs[0])
    try:
        phases.clock([run], [0.0])
        phases.pose([run], [0.0], Fleets())
        table = run.physics.box_poses()
        bodies = dict(zip(want, table[run.physics.box_slots(list(want)), 3]))
        truth = {w: run.fleet.ground_truth(w).heading for w in want}
    finally:
        run.close()
    assert {w: angle_error(h, bodies[w]) < TOL_RAD for w, h in want.items()} == dict.fromkeys(want, True), bodies
    assert {w: angle_error(h, truth[w]) < TOL_RAD for w, h in want.items()} == dict.fromkeys(want, True), truth
    assert abs(want["c3"]) < TOL_RAD and abs(abs(want["c1"]) - math.pi / 2) < 1e-9
