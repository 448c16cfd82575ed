"""Safe OpenDRIVE (.xodr) reader.

XML is read by the one safe reader, ``addt_dsl/xmlread.py`` (defusedxml: entity declarations
(billion laughs) and external entities are refused), into a tiny element tree that keeps the
source line of every element so that errors can point at it. Elements that do not change road geometry
(signals, objects, roadMark, userData, ...) are ignored; anything that does and cannot
be evaluated raises :class:`XodrError`.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import Optional, Union

import numpy as np

from addt_dsl import units
from addt_dsl.xmlread import XmlDocument, XmlReadError, read_xml

from .geometry import Arc, CubicProfile, Line, ParamPoly3, Poly3, Spiral
from .lanes import Lane, LaneSection
from . import limits as L
from .network import Connection, Junction, RoadNetwork
from .road import Controller, Road, RoadLink, Signal, SignalRef

_GEOMETRY_TAGS = ("line", "arc", "spiral", "poly3", "paramPoly3")


class XodrError(ValueError):
    """Invalid or unsupported OpenDRIVE content.

    ``element`` is the XML tag concerned, ``line`` its 1-based source line (None if
    unknown) and ``source`` the file name.
    """

    def __init__(self, message: str, element: Optional[str] = None, line: Optional[int] = None,
                 source: str = "<string>"):
        self.message = message
        self.element = element
        self.line = line
        self.source = source
        where = f"{source}:{line}" if line is not None else source
        what = f" <{element}>" if element else ""
        super().__init__(f"{where}:{what} {message}")


@dataclass
class _Node:
    """Minimal element: tag, attributes, children, source line."""

    tag: str
    attrs: dict
    line: int
    children: list = field(default_factory=list)

    def find(self, tag: str) -> Optional["_Node"]:
        for child in self.children:
            if child.tag == tag:
                return child
        return None

    def findall(self, tag: str) -> list["_Node"]:
        return [c for c in self.children if c.tag == tag]


def _parse_tree(data: Union[str, bytes], source: str) -> _Node:
    if isinstance(data, str):
        # Text is already decoded: hand expat UTF-8 and drop a conflicting declaration.
        if data.startswith("<?xml"):
            end = data.find("?>")
            data = data[end + 2:] if end >= 0 else data
        try:
            data = data.encode("utf-8")
        except UnicodeError as exc:
            raise XodrError(f"cannot decode the file: {exc}", line=None, source=source) from None
    try:
        doc = read_xml(data, forbid_dtd=False)  # a plain DOCTYPE is harmless; entities are what bite
    except XmlReadError as exc:
        if exc.kind == "unsafe":
            raise XodrError(
                f"refused unsafe XML ({exc.exception}: entity/DTD declarations and external "
                "references are not allowed in OpenDRIVE files)",
                element="!ENTITY", line=exc.line, source=source,
            ) from None
        if exc.kind == "decode":
            raise XodrError(f"cannot decode the file: {exc.detail}", line=exc.line, source=source) from None
        raise XodrError(f"malformed XML: {exc.reason}", line=exc.line, source=source) from None
    return _node(doc, doc.root)


def _node(doc: XmlDocument, element) -> _Node:
    """The element tree as _Nodes, without recursion (a deeply nested file is data, not a crash).
    A namespace is dropped ("{uri}road", "xodr:road" -> "road"): OpenDRIVE's tags are read bare."""
    def make(el) -> _Node:
        return _Node(el.tag.rsplit("}", 1)[-1].split(":", 1)[-1], dict(el.attrib), doc.line(el))

    root = make(element)
    todo = [(element, root)]
    while todo:
        el, node = todo.pop()
        for child in el:
            kid = make(child)
            node.children.append(kid)
            todo.append((child, kid))
    return root


class _Reader:
    """Turns the element tree into model objects; holds only the source name."""

    def __init__(self, source: str) -> None:
        self.source = source

    def err(self, node: _Node, message: str) -> XodrError:
        return XodrError(message, element=node.tag, line=node.line, source=self.source)

    def num(self, node: _Node, key: str, default: Optional[float] = None, bound: float = L.MAX_ABS_ATTRIBUTE,
            bound_name: str = "MAX_ABS_ATTRIBUTE") -> float:
        """A finite number no larger in magnitude than `bound` (absurd values are refused here,
        where they are read, not when something downstream overflows or allocates)."""
        raw = node.attrs.get(key)
        if raw is None:
            if default is not None:
                return default
            raise self.err(node, f"missing attribute {key!r}")
        try:
            value = float(raw)
        except ValueError:
            raise self.err(node, f"attribute {key}={raw!r} is not a number") from None
        if not math.isfinite(value):
            raise self.err(node, f"attribute {key}={raw!r} is not finite")
        if abs(value) > bound:
            raise self.err(node, f"attribute {key}: " + L.beyond(bound_name, abs(value), bound, "(absolute value)"))
        return value

    def coord(self, node: _Node, key: str, default: Optional[float] = None) -> float:
        return self.num(node, key, default, L.MAX_COORDINATE_M, "MAX_COORDINATE_M")

    def text(self, node: _Node, key: str, default: Optional[str] = None) -> str:
        raw = node.attrs.get(key, default)
        if raw is None:
            raise self.err(node, f"missing attribute {key!r}")
        return raw.strip()

    def cubic(self, nodes: list[_Node], s_key: str, before_first: str = "extrapolate") -> CubicProfile:
        starts, coeffs = [], []
        for n in nodes:
            starts.append(self.coord(n, s_key))
            # coefficients are bounded through the values they give (check_profiles)
            coeffs.append(tuple(self.num(n, k, bound=math.inf) for k in ("a", "b", "c", "d")))
        return CubicProfile(tuple(starts), tuple(coeffs), before_first=before_first)

    # ------------------------------------------------------------------ document

    def network(self, root: _Node) -> RoadNetwork:
        if root.tag != "OpenDRIVE":
            raise self.err(root, "root element must be <OpenDRIVE>")
        roads: dict[str, Road] = {}
        for node in root.findall("road"):
            road = self.road(node)
            if road.id in roads:
                raise self.err(node, f"duplicate road id {road.id!r}")
            roads[road.id] = road
        junctions = {}
        for node in root.findall("junction"):
            j = self.junction(node)
            junctions[j.id] = j
        controllers = {}
        for node in root.findall("controller"):
            cid = node.attrs.get("id", "").strip()
            if cid:  # OpenDRIVE's grouping of signals that switch together (`<control signalId>`)
                controllers[cid] = Controller(cid, node.attrs.get("name", ""), tuple(
                    c.attrs["signalId"].strip() for c in node.findall("control") if c.attrs.get("signalId")))
        return RoadNetwork(roads, junctions, source_name=self.source, controllers=controllers)

    def junction(self, node: _Node) -> Junction:
        connections = []
        for c in node.findall("connection"):
            contact = self.text(c, "contactPoint", "start")
            if contact not in ("start", "end"):
                raise self.err(c, f"contactPoint must be 'start' or 'end', got {contact!r}")
            links = tuple(
                (int(self.num(ll, "from")), int(self.num(ll, "to"))) for ll in c.findall("laneLink")
            )
            connections.append(
                Connection(
                    self.text(c, "id", ""),
                    self.text(c, "incomingRoad", ""),
                    self.text(c, "connectingRoad", "") or self.text(c, "linkedRoad", ""),
                    contact,
                    links,
                    direct="connectingRoad" not in c.attrs and "linkedRoad" in c.attrs,
                )
            )
        return Junction(self.text(node, "id"), node.attrs.get("name", ""), tuple(connections))

    def link(self, node: Optional[_Node]) -> Optional[RoadLink]:
        if node is None:
            return None
        etype = self.text(node, "elementType", "road")
        if etype not in ("road", "junction"):
            raise self.err(node, f"elementType must be 'road' or 'junction', got {etype!r}")
        contact = node.attrs.get("contactPoint")
        if contact is not None and contact not in ("start", "end"):
            raise self.err(node, f"contactPoint must be 'start' or 'end', got {contact!r}")
        return RoadLink(etype, self.text(node, "elementId"), contact)

    def road(self, node: _Node) -> Road:
        road_id = self.text(node, "id")
        length = self.num(node, "length", bound=math.inf)
        if length <= 0.0:
            raise self.err(node, f"road {road_id}: length must be > 0, got {length}")
        if length > L.MAX_ROAD_LENGTH_M:
            raise self.err(node, f"road {road_id}: length " + L.beyond(
                "MAX_ROAD_LENGTH_M", length, L.MAX_ROAD_LENGTH_M, "m", "split it into consecutive roads"))
        plan = node.find("planView")
        if plan is None or not plan.findall("geometry"):
            raise self.err(plan or node, f"road {road_id}: planView needs at least one <geometry>")
        geometries = tuple(self.geometry(g) for g in plan.findall("geometry"))
        if any(b.s0 < a.s0 for a, b in zip(geometries, geometries[1:])):
            raise self.err(plan, f"road {road_id}: geometries must be ordered by s")

        elev = node.find("elevationProfile")
        elevation = self.cubic(elev.findall("elevation") if elev else [], "s")
        lat = node.find("lateralProfile")
        superelevation = self.cubic(lat.findall("superelevation") if lat else [], "s")

        lanes = node.find("lanes")
        if lanes is None:
            raise self.err(node, f"road {road_id}: missing <lanes>")
        offset = self.cubic(lanes.findall("laneOffset"), "s", before_first="zero")
        sec_nodes = lanes.findall("laneSection")
        if not sec_nodes:
            raise self.err(lanes, f"road {road_id}: needs at least one <laneSection>")
        starts = [self.coord(sn, "s") for sn in sec_nodes]
        if any(b < a for a, b in zip(starts, starts[1:])):
            raise self.err(lanes, f"road {road_id}: lane sections must be ordered by s")
        ends = starts[1:] + [length]
        sections = tuple(self.section(sn, s0, s1) for sn, s0, s1 in zip(sec_nodes, starts, ends))

        link = node.find("link")
        rule = node.attrs.get("rule", "RHT")
        if rule not in ("RHT", "LHT"):
            raise self.err(node, f"rule must be 'RHT' or 'LHT', got {rule!r}")
        predecessor = self.link(link.find("predecessor")) if link else None
        successor = self.link(link.find("successor")) if link else None
        try:
            road = Road(
                road_id, length, geometries, sections,
                offset_profile=offset, elevation_profile=elevation,
                superelevation_profile=superelevation,
                name=node.attrs.get("name", ""), junction=node.attrs.get("junction", "-1").strip(),
                rule=rule,
                predecessor=predecessor,
                successor=successor,
                signals=self.signals(node.find("signals"), length),
                signal_refs=self.signal_refs(node.find("signals"), length),
                speed_limits=self.speed_limits(node),
            )
        except L.RoadLimitError as exc:
            at = plan.findall("geometry")[exc.geometry] if exc.geometry is not None else node
            raise self.err(at, str(exc)) from None
        except ValueError as exc:
            raise self.err(node, str(exc)) from None
        self.check_profiles(road, node, sec_nodes)
        return road

    def speed_limits(self, node: _Node) -> tuple[tuple[float, float], ...]:
        """(s, max [m/s]) of each road `<type>` with a numeric `<speed max>` (units m/s,
        km/h or mph; "no limit" and unknown units are skipped: the limit is unknown there)."""
        out = []
        for tn in node.findall("type"):
            speed = tn.find("speed")
            if speed is None:
                continue
            try:
                s, value = self.coord(tn, "s", 0.0), float(speed.attrs.get("max", ""))
            except (XodrError, ValueError):
                continue
            unit = units.UNITS.get(speed.attrs.get("unit", "m/s").strip())
            if unit is None or unit.dim != units.SPEED or not (math.isfinite(value) and value > 0):
                continue
            out.append((s, value * unit.factor))
        return tuple(sorted(out))

    def signals(self, node: Optional[_Node], length: float) -> tuple:
        """The road's `<signal>`s (positions, type, dynamic); references are `signal_refs`'."""
        if node is None:
            return ()
        out = []
        for sn, sid, s, t, validity in self._placed(node, "signal", length):
            out.append(Signal(sid, s, t, sn.attrs.get("name", ""),
                              sn.attrs.get("type", ""), sn.attrs.get("subtype", ""),
                              sn.attrs.get("dynamic", "no").strip().lower() == "yes",
                              sn.attrs.get("orientation", "none").strip() or "none", validity))
        return tuple(out)

    def signal_refs(self, node: Optional[_Node], length: float) -> tuple:
        """The road's `<signalReference>`s: another road's signal placed on this one
        (`RoadNetwork.placements` resolves them)."""
        if node is None:
            return ()
        return tuple(SignalRef(sid, s, t, sn.attrs.get("orientation", "none").strip() or "none", validity)
                     for sn, sid, s, t, validity in self._placed(node, "signalReference", length))

    def _placed(self, node: _Node, tag: str, length: float):
        """(element, id, s, t, validity) of each `tag` child with a position on the road."""
        for sn in node.findall(tag):
            try:
                s = self.coord(sn, "s")
                t = self.coord(sn, "t", 0.0)
                sid = self.text(sn, "id")
            except XodrError:
                continue  # signals are metadata for the geometry: one without a position is skipped
            if not 0.0 <= s <= length + 1e-6:
                continue
            validity = None
            vn = sn.find("validity")
            if vn is not None:
                try:
                    lo, hi = int(self.num(vn, "fromLane")), int(self.num(vn, "toLane"))
                    validity = (min(lo, hi), max(lo, hi))
                except XodrError:
                    validity = None  # a malformed validity: the signal governs its whole side
            yield sn, sid, s, t, validity

    def check_profiles(self, road: Road, node: _Node, sec_nodes: list[_Node]) -> None:
        """Lane widths, laneOffset, elevation and superelevation stay within their limits
        along the whole road (each cubic piece is probed at 17 points)."""
        lanes = node.find("lanes")
        checks = [(road.offset_profile, 0.0, road.length, L.MAX_LANE_OFFSET_M, "MAX_LANE_OFFSET_M", "laneOffset",
                   lanes, "m"),
                  (road.elevation_profile, 0.0, road.length, L.MAX_ELEVATION_M, "MAX_ELEVATION_M", "elevation",
                   node.find("elevationProfile") or node, "m"),
                  (road.superelevation_profile, 0.0, road.length, L.MAX_SUPERELEVATION_RAD,
                   "MAX_SUPERELEVATION_RAD", "superelevation", node.find("lateralProfile") or node, "rad")]
        for sec, sn in zip(road.sections, sec_nodes):
            # Lane ids were parsed (and checked) by lane(); map them back to their elements.
            nodes = {int(float(n.attrs["id"])): n for side in (sn.find("left"), sn.find("right")) if side
                     for n in side.findall("lane")}
            for lane in sec.left + sec.right:
                checks.append((lane.width, 0.0, sec.s1 - sec.s0, L.MAX_LANE_WIDTH_M, "MAX_LANE_WIDTH_M",
                               f"lane {lane.id} width", nodes.get(lane.id, sn), "m"))
        for profile, lo, hi, limit, name, what, at, unit in checks:
            worst = _profile_max(profile, lo, hi)
            if worst > limit:
                raise self.err(at, f"road {road.id}: {what} " + L.beyond(name, worst, limit, unit))

    def geometry(self, node: _Node):
        s0, x0, y0 = (self.coord(node, k) for k in ("s", "x", "y"))
        hdg = self.num(node, "hdg")
        length = self.num(node, "length", bound=L.MAX_ROAD_LENGTH_M, bound_name="MAX_ROAD_LENGTH_M")
        if length < 0.0:
            raise self.err(node, f"geometry length must be >= 0, got {length}")
        kinds = [c for c in node.children if c.tag in _GEOMETRY_TAGS]
        others = [c for c in node.children if c.tag not in _GEOMETRY_TAGS and c.tag != "userData"]
        if others:
            raise self.err(others[0], "unsupported planView geometry type")
        if len(kinds) != 1:
            raise self.err(node, f"<geometry> needs exactly one of {', '.join(_GEOMETRY_TAGS)}; found {len(kinds)}")
        g = kinds[0]
        try:
            if g.tag == "line":
                return Line(s0, x0, y0, hdg, length)
            # Curvatures are bounded by the turn they give (geometry._check_turn), not by magnitude.
            if g.tag == "arc":
                return Arc(s0, x0, y0, hdg, length, self.num(g, "curvature", bound=math.inf))
            if g.tag == "spiral":
                return Spiral(s0, x0, y0, hdg, length, self.num(g, "curvStart", bound=math.inf),
                              self.num(g, "curvEnd", bound=math.inf))
            if g.tag == "poly3":
                return Poly3(s0, x0, y0, hdg, length, *(self.num(g, k) for k in "abcd"))
            p_range = g.attrs.get("pRange", "normalized").strip()
            if p_range not in ("arcLength", "normalized"):
                raise self.err(g, f"pRange must be 'arcLength' or 'normalized', got {p_range!r}")
            coeffs = [self.num(g, f"{c}{ax}") for ax in "UV" for c in "abcd"]
            return ParamPoly3(s0, x0, y0, hdg, length, *coeffs, p_range=p_range)
        except ValueError as exc:
            if isinstance(exc, XodrError):
                raise
            raise self.err(g, str(exc)) from None

    def section(self, node: _Node, s0: float, s1: float) -> LaneSection:
        sides = {}
        for side_tag, sign in (("left", 1), ("right", -1)):
            side = node.find(side_tag)
            lanes = [self.lane(n) for n in side.findall("lane")] if side else []
            for lane, n in zip(lanes, side.findall("lane") if side else []):
                if lane.id * sign <= 0:
                    raise self.err(n, f"lane id {lane.id} does not belong to <{side_tag}>")
            sides[side_tag] = tuple(sorted(lanes, key=lambda ln: abs(ln.id)))
        center = node.find("center")
        center_lane = center.find("lane") if center else None
        try:
            return LaneSection(
                s0, s1, left=sides["left"], right=sides["right"],
                center_type=center_lane.attrs.get("type", "none") if center_lane else "none",
            )
        except ValueError as exc:
            raise self.err(node, str(exc)) from None

    def lane(self, node: _Node) -> Lane:
        lane_id = int(self.num(node, "id"))
        widths = node.findall("width")
        if not widths:
            if node.findall("border"):
                raise self.err(node, f"lane {lane_id}: <border> lane geometry is not supported (use <width>)")
            raise self.err(node, f"lane {lane_id}: missing <width>")
        link = node.find("link")
        pred = tuple(int(self.num(p, "id")) for p in link.findall("predecessor")) if link else ()
        succ = tuple(int(self.num(p, "id")) for p in link.findall("successor")) if link else ()
        level = node.attrs.get("level", "false").strip().lower() in ("true", "1")
        return Lane(
            lane_id, node.attrs.get("type", "none").strip(), self.cubic(widths, "sOffset"), level, pred, succ
        )


def _profile_max(profile: CubicProfile, lo: float, hi: float) -> float:
    """Largest |f| of a piecewise cubic over [lo, hi], probed at 17 points per piece."""
    if not profile.starts_sorted or hi <= lo:
        return 0.0
    cuts = sorted({lo, hi, *(min(max(s, lo), hi) for s in profile.starts_sorted)})
    probe = np.concatenate([np.linspace(a, b, 17) for a, b in zip(cuts, cuts[1:])] or [np.array([lo])])
    with np.errstate(all="ignore"):
        values = np.abs(np.asarray(profile(probe), dtype=float))
    return float(np.max(values)) if np.all(np.isfinite(values)) else math.inf


def parse_xodr(text: Union[str, bytes], source_name: str = "<string>") -> RoadNetwork:
    """Parse OpenDRIVE XML text (str or bytes) into a :class:`RoadNetwork`."""
    root = _parse_tree(text, source_name)
    return _Reader(source_name).network(root)


def load_xodr(path: Union[str, os.PathLike]) -> RoadNetwork:
    """Read and parse an ``.xodr`` file."""
    with open(path, "rb") as fh:
        data = fh.read()
    return parse_xodr(data, source_name=str(path))
