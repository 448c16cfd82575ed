"""Road network: roads by id, junctions, chain following, world -> road coordinates."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Optional, Sequence

import numpy as np

from .geometry import CubicProfile, Geometry, end_pose, place
from .lanes import Lane, LaneSection
from .road import ON_ROAD_LONG_TOL_M, Controller, Road

CONTACT_POINTS = ("start", "end")


@dataclass(frozen=True)
class RoadCoords:
    """Road coordinates of a world point: ``t`` [m] is the lateral offset from the
    reference line (positive left), ``lane_id`` the lane containing it or None."""

    road_id: str
    lane_id: Optional[int]
    s: float
    t: float


@dataclass(frozen=True)
class RoadCoordsArray:
    """Vectorised :class:`RoadCoords`; ``lane_id`` 0 means "outside all lanes"."""

    road_id: np.ndarray  # object array of str
    lane_id: np.ndarray  # int
    s: np.ndarray  # [m]
    t: np.ndarray  # [m]
    distance_off_road: np.ndarray  # [m] distance to the nearest road's lane band, 0 inside


@dataclass(frozen=True)
class Connection:
    """``<junction><connection>``: from ``incoming_road`` into ``connecting_road``, entering
    it at ``contact_point`` ("start"/"end"); ``lane_links`` are (from, to) lane ids. In a
    direct junction (OpenDRIVE 1.7 ``type="direct"``) ``connecting_road`` is the
    ``linkedRoad``: the incoming road leads straight into it (``direct`` True)."""

    id: str
    incoming_road: str
    connecting_road: str
    contact_point: str
    lane_links: tuple[tuple[int, int], ...] = ()
    direct: bool = False


@dataclass(frozen=True)
class Junction:
    id: str
    name: str = ""
    connections: tuple[Connection, ...] = ()


def _other_end(contact: str) -> str:
    return "end" if contact == "start" else "start"


@dataclass(frozen=True)
class RoadNetwork:
    roads: dict[str, Road]
    junctions: dict[str, Junction] = field(default_factory=dict)
    source_name: str = "<string>"
    controllers: dict[str, Controller] = field(default_factory=dict)  # `<controller>` by id

    def signal(self, signal_id: str):
        """``(road_id, Signal)`` of the signal with this id, or None."""
        for road in self.roads.values():
            for sig in road.signals:
                if sig.id == signal_id:
                    return road.id, sig
        return None

    def placements(self, signal_id: str | None = None) -> list:
        """``(road_id, Signal)`` of every placement of a signal (of `signal_id`, or all):
        where it stands, and each `<signalReference>` to it, which places it on the
        referencing road with the reference's s, t, orientation and validity (OpenDRIVE 1.6,
        13.8; `Signal.reference`). Roads in their numeric order, a road's own signals before
        its references; a reference to no signal of the map is skipped."""
        own = {}
        for road in self.roads.values():
            for sig in road.signals:
                own.setdefault(sig.id, sig)
        out = []
        for road_id in sorted(self.roads, key=_natural_key):
            road = self.roads[road_id]
            out.extend((road_id, sig) for sig in road.signals if signal_id in (None, sig.id))
            for ref in road.signal_refs:
                sig = own.get(ref.id)
                if sig is not None and signal_id in (None, ref.id):
                    out.append((road_id, replace(sig, s=ref.s, t=ref.t, orientation=ref.orientation,
                                                 validity=ref.validity, reference=True)))
        return out

    def signal_ids(self, dynamic_only: bool = False) -> list[str]:
        return [sig.id for road in self.roads.values() for sig in road.signals
                if sig.dynamic or not dynamic_only]

    def road(self, road_id) -> Road:
        try:
            return self.roads[str(road_id)]
        except KeyError:
            raise KeyError(f"no road {road_id!r} in {self.source_name} (roads: {sorted(self.roads)})") from None

    # Thin delegations so that callers can stay at the network level.
    def reference_pose(self, road_id, s):
        """``(x, y, heading)`` [m, m, rad] of the reference line of ``road_id`` at ``s`` [m]."""
        return self.road(road_id).reference_pose(s)

    def lane_center(self, road_id, lane_id: int, s):
        """``(x, y, heading)`` [m, m, rad] of the centre line of ``lane_id`` at ``s`` [m]."""
        return self.road(road_id).lane_center(lane_id, s)

    def lane_width(self, road_id, lane_id: int, s):
        """Width [m] of ``lane_id`` at ``s`` [m]."""
        return self.road(road_id).lane_width(lane_id, s)

    def curvature(self, road_id, s):
        """Reference-line curvature [1/m] at ``s`` [m]."""
        return self.road(road_id).curvature(s)

    def elevation(self, road_id, s):
        """Reference-line height [m] at ``s`` [m]."""
        return self.road(road_id).elevation(s)

    # ---------------------------------------------------------- world -> road

    def to_road_coords(self, x: float, y: float) -> RoadCoords:
        """Road coordinates of the world point ``(x, y)`` [m].

        The road is the one whose lane band (outermost borders) is nearest to the point
        (0 when inside); ties (e.g. overlapping roads) go to the nearest reference line.
        """
        res = self.to_road_coords_array(np.asarray([x], dtype=float), np.asarray([y], dtype=float))
        lane = int(res.lane_id[0])
        return RoadCoords(str(res.road_id[0]), lane or None, float(res.s[0]), float(res.t[0]))

    def to_road_coords_array(self, x, y, road_ids: Optional[Sequence[str]] = None) -> RoadCoordsArray:
        """Vectorised :meth:`to_road_coords` for arrays of points (optionally restricted to
        ``road_ids``)."""
        x = np.asarray(x, dtype=float)
        y = np.asarray(y, dtype=float)
        shape = np.broadcast(x, y).shape
        px, py = np.broadcast_to(x, shape).ravel(), np.broadcast_to(y, shape).ravel()
        ids = [str(r) for r in road_ids] if road_ids is not None else list(self.roads)
        if not ids:
            raise ValueError(f"{self.source_name}: network has no roads")
        best_key = np.full(px.shape, np.inf)
        best_ref = np.full(px.shape, np.inf)
        out_road = np.empty(px.shape, dtype=object)
        out_s, out_t, out_lane = np.zeros(px.shape), np.zeros(px.shape), np.zeros(px.shape, dtype=int)
        out_off = np.zeros(px.shape)
        for rid in ids:
            road = self.road(rid)
            s, t, f = road.project_array(px, py)
            lo, hi = road.road_band_t(s)
            lateral_out = np.maximum(0.0, np.maximum(t - hi, lo - t))
            off_end = np.where(np.abs(f) > ON_ROAD_LONG_TOL_M, np.abs(f), 0.0)
            key = np.hypot(off_end, lateral_out)
            ref = np.hypot(f, t)
            better = (key < best_key - 1e-9) | ((np.abs(key - best_key) <= 1e-9) & (ref < best_ref))
            if not np.any(better):
                continue
            lanes = road.lanes_at(s, t)
            lanes = np.where(off_end > 0.0, 0, lanes)
            best_key = np.where(better, key, best_key)
            best_ref = np.where(better, ref, best_ref)
            out_road[better] = road.id
            out_s = np.where(better, s, out_s)
            out_t = np.where(better, t, out_t)
            out_lane = np.where(better, lanes, out_lane)
            out_off = np.where(better, key, out_off)
        return RoadCoordsArray(
            out_road.reshape(shape), out_lane.reshape(shape), out_s.reshape(shape),
            out_t.reshape(shape), out_off.reshape(shape),
        )

    # ------------------------------------------------------------- topology

    def next_roads(self, road_id, contact: str = "end") -> list[tuple[str, str]]:
        """Roads reachable by leaving ``road_id`` at its ``contact`` end ("end" when
        driving along +s, "start" when driving against s).

        Returns ``[(next_road_id, entry_contact), ...]`` where ``entry_contact`` is the end
        ("start"/"end") of the next road that touches this one; through a junction there is
        one entry per matching connection (sorted by connection id).
        """
        if contact not in CONTACT_POINTS:
            raise ValueError(f"contact must be 'start' or 'end', got {contact!r}")
        road = self.road(road_id)
        link = road.successor if contact == "end" else road.predecessor
        if link is None:
            return []
        if link.element_type == "road":
            if link.element_id not in self.roads:
                return []
            return [(link.element_id, link.contact_point or "start")]
        if link.element_type == "junction":
            junction = self.junctions.get(link.element_id)
            if junction is None:
                return []
            found = [
                (c.connecting_road, c.contact_point)
                for c in sorted(junction.connections, key=lambda c: _natural_key(c.id))
                if c.incoming_road == road.id and c.connecting_road in self.roads
            ]
            return list(dict.fromkeys(found))
        return []

    def next_road(self, road_id, contact: str = "end") -> Optional[tuple[str, str]]:
        """First of :meth:`next_roads`, or None at a dead end."""
        nxt = self.next_roads(road_id, contact)
        return nxt[0] if nxt else None

    def follow_chain(self, road_id, contact: str = "end", max_roads: int = 1000) -> list[tuple[str, int]]:
        """Route along successive roads starting on ``road_id`` and leaving it at ``contact``.

        Returns ``[(road_id, direction), ...]`` with direction +1 (driving along +s) or -1;
        takes the first option at junctions and stops at dead ends or on a repeated road.
        """
        route = [(str(road_id), 1 if contact == "end" else -1)]
        seen = {str(road_id)}
        leave = contact
        while len(route) < max_roads:
            nxt = self.next_road(route[-1][0], leave)
            if nxt is None or nxt[0] in seen:
                break
            rid, entry = nxt
            route.append((rid, 1 if entry == "start" else -1))
            seen.add(rid)
            leave = _other_end(entry)
        return route


def _natural_key(text: str):
    return (0, int(text), "") if text.lstrip("-").isdigit() else (1, 0, text)


# ------------------------------------------------------------- inline roads


def build_road(
    road_id: str,
    segments: Sequence[Geometry],
    left_lanes: int,
    right_lanes: int,
    lane_width_m: float,
    lane_offset_m: float = 0.0,
    start: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> RoadNetwork:
    """Build a one-road network from code.

    ``segments`` are primitives from the factories :func:`line`, :func:`arc`,
    :func:`spiral`, :func:`poly3`, :func:`param_poly3` (or any primitive dataclass; its
    placement is ignored). They are chained so that each starts at the previous one's end
    pose with the same tangent; the first starts at ``start = (x, y, heading)``
    [m, m, rad]. One lane section with ``left_lanes``/``right_lanes`` lanes of constant
    ``lane_width_m`` [m], all of type ``driving``; ``lane_offset_m`` [m] shifts the centre
    lane (constant laneOffset).
    """
    if not segments:
        raise ValueError("build_road needs at least one segment")
    if left_lanes < 0 or right_lanes < 0 or left_lanes + right_lanes == 0:
        raise ValueError(f"need >= 1 lane and non-negative counts, got left={left_lanes}, right={right_lanes}")
    if not (lane_width_m > 0.0 and math.isfinite(lane_width_m)):
        raise ValueError(f"lane_width_m must be > 0, got {lane_width_m!r}")
    if not math.isfinite(lane_offset_m):
        raise ValueError(f"lane_offset_m must be finite, got {lane_offset_m!r}")
    x, y, h = (float(v) for v in start)
    s = 0.0
    placed: list[Geometry] = []
    for seg in segments:
        if not seg.length > 0.0:
            raise ValueError(f"segment {seg!r} must have length > 0 m")
        geom = place(seg, s, x, y, h)
        placed.append(geom)
        x, y, h = end_pose(geom)
        s += geom.length
    width = CubicProfile.constant(lane_width_m)
    section = LaneSection(
        0.0,
        s,
        left=tuple(Lane(i, "driving", width) for i in range(1, left_lanes + 1)),
        right=tuple(Lane(-i, "driving", width) for i in range(1, right_lanes + 1)),
    )
    offset = CubicProfile((0.0,), ((float(lane_offset_m), 0.0, 0.0, 0.0),), before_first="zero")
    road = Road(str(road_id), s, tuple(placed), (section,), offset_profile=offset)
    return RoadNetwork({road.id: road}, {}, source_name=f"<inline road {road_id}>")
