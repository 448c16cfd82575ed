"""The road of a run as an OpenDRIVE file (written with `scenariogeneration.xodr`).

Inline roads (`road NAME { line ...; lanes ... }`) become one `<road>` each, numbered
1, 2, ... in declaration order, every one starting at the origin heading east (as the
runtime builds them: `addt_dsl.road.roadspec.build_network`); one lane section, constant lane
widths, a constant lane offset. Imported maps are copied as they are (their road ids
kept). A plan mixing inline and imported roads, or importing several files, has no
single OpenDRIVE file: `ExportError`.
"""

from __future__ import annotations

import datetime
import os
from dataclasses import dataclass, field
from pathlib import Path
from xml.etree import ElementTree as ET  # serialises trees we build; untrusted XML is read with defusedxml

from scenariogeneration import xodr

from addt_dsl.plan import RoadPlan, ScenarioPlan, SignalPlan


def creation_date() -> datetime.datetime:
    """The date in an exported file's header (.xosc FileHeader, .xodr header): `SOURCE_DATE_EPOCH`
    (the reproducible-builds convention) when set, else the Unix epoch, so that exporting one
    RunSpec twice gives the same bytes (an exported counterexample diffs clean in version control)."""
    try:
        epoch_s = int(os.environ.get("SOURCE_DATE_EPOCH", "0"))
    except ValueError:
        epoch_s = 0
    return datetime.datetime.fromtimestamp(epoch_s, tz=datetime.timezone.utc).replace(tzinfo=None)


class ExportError(Exception):
    """The run cannot be exported (message for the user)."""


@dataclass
class RoadFile:
    """The OpenDRIVE file of a run: its name, its text and each plan road's id in it."""

    name: str
    text: str
    road_ids: dict[str, str] = field(default_factory=dict)  # plan road name -> OpenDRIVE road id
    generated: bool = True  # False: an imported map, copied
    # Signal declared in the language (`signal s1 road r at 150 m`) -> its `<signal id>` in the
    # generated file: numbered 1, 2, ... (esmini reads signal ids as integers).
    signal_ids: dict[str, str] = field(default_factory=dict)


def _geometry(seg):
    if seg.kind == "line":
        return xodr.Line(seg.length_m)
    if seg.kind == "arc":
        return xodr.Arc(seg.curvature_per_m, length=seg.length_m)
    if seg.kind == "spiral":
        return xodr.Spiral(seg.curv_start_per_m, seg.curv_end_per_m, length=seg.length_m)
    if seg.kind == "param_poly3":
        return xodr.ParamPoly3(*seg.coefficients, prange="arcLength", length=seg.length_m)
    raise ExportError(f"road geometry {seg.kind!r} has no OpenDRIVE writer")


# An inline signal as an OpenDRIVE traffic light: type 1000001 (red, yellow, green lamps).
LIGHT_TYPE = "1000001"


def _signal(sig: SignalPlan) -> xodr.Signal:
    """`signal NAME road R at S [lane L]`: facing traffic along +s (no lane, or a right-hand
    lane) or against it (a left-hand lane), governing lane L only when one is given."""
    against = bool(sig.lanes) and sig.lanes[0] > 0
    # No id here: scenariogeneration numbers signals per process; `road_file` writes ours.
    out = xodr.Signal(sig.s_m, 0.0, "OpenDRIVE", LIGHT_TYPE, name=sig.name, dynamic=xodr.Dynamic.yes,
                      orientation=xodr.Orientation.negative if against else xodr.Orientation.positive)
    if sig.lanes:
        out.add_validity(sig.lanes[0], sig.lanes[0])
    return out


def _road(road: RoadPlan, road_id: int) -> xodr.Road:
    planview = xodr.PlanView(0.0, 0.0, 0.0)
    for seg in road.segments:
        planview.add_geometry(_geometry(seg))
    mark = xodr.RoadMark(xodr.RoadMarkType.solid, 0.12)
    center = xodr.Lane()
    center.add_roadmark(mark)
    section = xodr.LaneSection(0, center)
    for _ in range(road.left_lanes):
        lane = xodr.Lane(a=road.lane_width_m)
        lane.add_roadmark(xodr.RoadMark(xodr.RoadMarkType.broken, 0.12))
        section.add_left_lane(lane)
    for _ in range(road.right_lanes):
        lane = xodr.Lane(a=road.lane_width_m)
        lane.add_roadmark(xodr.RoadMark(xodr.RoadMarkType.broken, 0.12))
        section.add_right_lane(lane)
    lanes = xodr.Lanes()
    lanes.add_lanesection(section)
    if road.lane_offset_m:
        lanes.add_laneoffset(xodr.LaneOffset(0.0, road.lane_offset_m))
    return xodr.Road(road_id, planview, lanes, name=road.name)


def road_file(plan: ScenarioPlan, stem: str) -> RoadFile:
    """The OpenDRIVE file for `plan`'s roads, named after `stem` for inline roads."""
    imported = [r for r in plan.roads if r.source == "xodr"]
    if imported:
        if len(imported) != len(plan.roads):
            raise ExportError("the scenario mixes inline roads and imported maps; OpenSCENARIO "
                              "references one OpenDRIVE file")
        texts = {r.xodr_text for r in imported}
        if len(texts) != 1:
            raise ExportError("the scenario imports several OpenDRIVE files; OpenSCENARIO references one")
        name = Path(imported[0].xodr_file or f"{stem}.xodr").name
        return RoadFile(name=name, text=imported[0].xodr_text or "", generated=False,
                        road_ids={r.name: str(r.xodr_road_id) for r in imported})
    odr = xodr.OpenDrive(plan.name, revMajor="1", revMinor="8")
    ids = {}
    signal_ids = {sig.name: str(i) for i, sig in enumerate(plan.signals, start=1)}
    for i, road in enumerate(plan.roads, start=1):
        built = _road(road, i)
        for sig in plan.signals:
            if sig.road == road.name:
                built.add_signal(_signal(sig))
        odr.add_road(built)
        ids[road.name] = str(i)
    odr.adjust_startpoints()
    element = odr.get_element()
    # scenariogeneration stamps the header with the time of writing: the export's own date instead.
    element.find("header").set("date", creation_date().isoformat(timespec="seconds"))
    for sig in element.iter("signal"):
        # scenariogeneration always writes a country; OpenDRIVE 1.8 takes ISO 3166 codes only
        # and 1000001 is OpenDRIVE's own generic traffic light: the optional attribute goes.
        sig.attrib.pop("country", None)
        # Its ids are unique per process, not per file (a second export would renumber): ours.
        sig.set("id", signal_ids[sig.get("name")])
    return RoadFile(name=f"{stem}.xodr", text=xml_text(element), road_ids=ids, signal_ids=signal_ids)


def xml_text(element) -> str:
    """An element tree we built, as indented XML text with a declaration."""
    ET.indent(element)
    return '<?xml version="1.0" encoding="utf-8"?>\n' + ET.tostring(element, encoding="unicode") + "\n"
