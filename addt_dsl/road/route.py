"""Routes through a road network: road ids and junction turns → lane-following legs.

A route is what a driver would say: the roads in order (`1 -> 3`), optionally with
the connecting road inside a junction (`1 -> 505 -> 3`) or a turn instead of it
(`1 -> left -> ...`: the connection at the next junction that turns left). `resolve_route`
checks it against the network and expands it into `Leg`s: one per (road, lane
section), each with its driving direction (+1 along s), its s-range in driving order
and the road lane id the route lane has there. Lanes are followed across lane sections
(lane ids renumbered by `<lane><link>`), road links (`<lane><link>` of the last
section) and junctions (`<laneLink>`); where a map gives no link the route continues in
the lane whose centre is nearest to where the previous one ended.

Driving direction follows OpenDRIVE: with right-hand traffic (`rule="RHT"`, the default)
lanes with negative ids run along +s and positive ids against it; left-hand traffic the
other way round (`Road.travel_direction`).

Pure numpy, no simulator: the compiler checks routes with it and the runtime builds its
paths from the same legs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

from .network import Connection, RoadNetwork
from .road import Road

TURNS = ("left", "right", "straight")
TURN_THRESHOLD_RAD = math.radians(30.0)  # heading change that makes a connection a turn


@dataclass(frozen=True)
class Leg:
    """One stretch of a route: ``road_id`` driven in ``direction`` (+1 along s, -1
    against) from road station ``s_from`` to ``s_to`` [m] (in driving order, so
    ``s_to < s_from`` when ``direction`` is -1), in road lane ``lane``."""

    road_id: str
    direction: int
    s_from: float
    s_to: float
    lane: int

    @property
    def length_m(self) -> float:
        return abs(self.s_to - self.s_from)


class RouteError(ValueError):
    """A route the network does not have; ``stop`` is the index of the offending stop
    in the route as written, ``hint`` says what the map offers there."""

    def __init__(self, message: str, stop: int = 0, hint: str = ""):
        super().__init__(message)
        self.message, self.stop, self.hint = message, stop, hint


@dataclass(frozen=True)
class _Exit:
    """A way out of a road end: into ``road_id`` entering at ``contact``; through
    ``connection`` (a junction's) when there is one."""

    road_id: str
    contact: str
    junction: str | None
    connection: Connection | None


def _other(contact: str) -> str:
    return "start" if contact == "end" else "end"


def exits(network: RoadNetwork, road_id: str, leave: str) -> list[_Exit]:
    """Every way out of ``road_id`` at its ``leave`` end ("end" driving along +s)."""
    road = network.road(road_id)
    link = road.successor if leave == "end" else road.predecessor
    if link is None:
        return []
    if link.element_type == "road":
        if link.element_id not in network.roads:
            return []
        return [_Exit(link.element_id, link.contact_point or "start", None, None)]
    junction = network.junctions.get(link.element_id)
    if junction is None:
        return []
    return [_Exit(c.connecting_road, c.contact_point, junction.id, c) for c in junction.connections
            if c.incoming_road == road.id and c.connecting_road in network.roads]


def turn_of(network: RoadNetwork, road_id: str, contact: str) -> str:
    """`left`, `right` or `straight`: the heading change along a (connecting) road
    driven from its ``contact`` end."""
    road = network.road(road_id)
    _, _, h0 = road.reference_pose(0.0)
    _, _, h1 = road.reference_pose(road.length)
    change = math.remainder(float(h1) - float(h0), math.tau)
    if contact == "end":
        change = -change
    if change > TURN_THRESHOLD_RAD:
        return "left"
    if change < -TURN_THRESHOLD_RAD:
        return "right"
    return "straight"


def describe_exits(network: RoadNetwork, road_id: str, leave: str) -> str:
    """What a road end leads to, for hints: `road 0 (end) leads to: road 5; junction 4:
    8 (right, to road 1), ...`."""
    outs = exits(network, road_id, leave)
    if not outs:
        return f"road {road_id} ends at its {leave} (no link)"
    parts = []
    for e in outs:
        if e.connection is None or e.connection.direct:
            parts.append(f"road {e.road_id}")
            continue
        after = [x.road_id for x in exits(network, e.road_id, _other(e.contact))]
        to = f", to road {', '.join(after)}" if after else ""
        parts.append(f"{e.road_id} ({turn_of(network, e.road_id, e.contact)}{to})")
    where = f"junction {outs[0].junction}" if outs[0].junction else "its link"
    return f"road {road_id} leaves at its {leave} into {where}: " + "; ".join(parts)


def _lane_exists(road: Road, lane: int, s: float) -> bool:
    return lane != 0 and lane in road.lane_ids(s)


def _nearest_lane(road: Road, s: float, t: float, direction: int) -> int | None:
    """The lane driven in ``direction`` whose centre at ``s`` is nearest to ``t``."""
    best, best_d = None, math.inf
    for lane in road.driving_lane_ids(s) or road.lane_ids(s):
        if road.travel_direction(lane) != direction:
            continue
        d = abs(float(road.lane_center_t(lane, s)) - t)
        if d < best_d:
            best, best_d = lane, d
    return best


def _sections_from(road: Road, s: float, direction: int) -> list[tuple[int, float, float]]:
    """(section index, s_from, s_to) of the sections from ``s`` to the road's end in
    ``direction`` (driving order)."""
    out = []
    for i, sec in enumerate(road.sections):
        if direction > 0 and sec.s1 > s:
            out.append((i, max(sec.s0, s), sec.s1))
        elif direction < 0 and sec.s0 < s:
            out.append((i, min(sec.s1, s), sec.s0))
    return out if direction > 0 else out[::-1]


def _follow_road(road: Road, lane: int, s_start: float, direction: int) -> list[Leg]:
    """Legs along one road from ``s_start`` to its end in ``direction``, following
    ``lane`` through the lane sections."""
    legs: list[Leg] = []
    prev_sec = None
    for i, s_from, s_to in _sections_from(road, s_start, direction):
        sec = road.sections[i]
        if prev_sec is not None:
            lane = _next_section_lane(road, prev_sec, sec, lane, direction, s_from)
        mid = 0.5 * (s_from + s_to)
        if not _lane_exists(road, lane, mid):
            raise RouteError(f"road {road.id} has no lane {lane} at s = {mid:.1f} m",
                             hint=f"lanes there: {', '.join(str(i) for i in road.lane_ids(mid))}")
        if abs(s_to - s_from) > 1e-9:
            legs.append(Leg(road.id, direction, s_from, s_to, lane))
        prev_sec = sec
    return legs


def _next_section_lane(road: Road, prev, sec, lane: int, direction: int, s_boundary: float) -> int:
    own = prev.lane(lane)
    linked = (own.successors if direction > 0 else own.predecessors) if own is not None else ()
    ds = s_boundary - sec.s0
    for cand in linked:
        if sec.lane(cand) is not None and float(sec.lane(cand).width(ds)) > 1e-9:
            return cand
    if sec.lane(lane) is not None and float(sec.lane(lane).width(ds)) > 1e-9 and not linked:
        return lane
    # The lane ends here: continue in the nearest lane of the same direction.
    s_prev = s_boundary - direction * 1e-6
    t = float(road.lane_center_t(lane, min(max(s_prev, 0.0), road.length)))
    nearest = _nearest_lane(road, min(max(s_boundary + direction * 1e-6, 0.0), road.length), t, direction)
    return nearest if nearest is not None else lane


def _entry_lane(network: RoadNetwork, leg: Leg, ex: _Exit) -> int | None:
    """The route lane on the road entered through ``ex`` from the end of ``leg``."""
    road_in = network.road(ex.road_id)
    s_in = 0.0 if ex.contact == "start" else road_in.length
    direction_in = 1 if ex.contact == "start" else -1
    if ex.connection is not None and ex.connection.lane_links:
        for a, b in ex.connection.lane_links:
            if a == leg.lane:
                return b if _lane_exists(road_in, b, s_in) else None
        return None
    prev = network.road(leg.road_id)
    sec = prev.section_at(leg.s_to)
    own = sec.lane(leg.lane)
    linked = (own.successors if leg.direction > 0 else own.predecessors) if own is not None else ()
    for cand in linked:
        if _lane_exists(road_in, cand, s_in):
            return cand
    same = leg.lane * leg.direction * direction_in
    if _lane_exists(road_in, same, s_in) and road_in.travel_direction(same) == direction_in:
        return same
    # No link: the lane nearest to where this one ends.
    x, y, _ = prev.lane_center(leg.lane, leg.s_to)
    s, t = road_in.project(float(x), float(y))
    return _nearest_lane(road_in, s, t, direction_in)


def _lanes_taken(ex: _Exit) -> str:
    links = ex.connection.lane_links if ex.connection is not None else ()
    return ", ".join(str(a) for a, _ in links) or "?"


def resolve_route(network: RoadNetwork, stops: Sequence[str], lane: int, s_start: float | None = None,
                  reverse: bool = False
                  ) -> tuple[list[str], list[Leg]]:
    """Check a route and expand it: (every road id in driving order, connecting roads
    included; the legs). ``lane`` is the road lane id on the first road at ``s_start``
    (None: the first road's entry end). Raises `RouteError`."""
    if not stops:
        raise RouteError("a route needs at least one road")
    if stops[0] in TURNS:
        raise RouteError(f"a route starts on a road, not with a turn ('{stops[0]}')")
    first = str(stops[0])
    if first not in network.roads:
        raise RouteError(f"no road '{first}' in {network.source_name}", 0,
                         f"roads: {', '.join(sorted(network.roads, key=_key))}")
    road = network.road(first)
    if lane == 0:
        raise RouteError("lane 0 carries no traffic", 0)
    direction = -road.travel_direction(lane) if reverse else road.travel_direction(lane)
    if s_start is None:
        s_start = 0.0 if direction > 0 else road.length
    s_start = min(max(float(s_start), 0.0), road.length)
    legs = _start_legs(road, lane, s_start, direction)
    roads = [first]
    i = 1
    while i < len(stops):
        stop = str(stops[i])
        last = legs[-1]
        leave = "end" if last.direction > 0 else "start"
        outs = exits(network, last.road_id, leave)
        hint = describe_exits(network, last.road_id, leave)
        if stop in TURNS:
            chosen = [e for e in outs if e.connection is not None and not e.connection.direct
                      and turn_of(network, e.road_id, e.contact) == stop]
            if not chosen:
                raise RouteError(f"no connection turns {stop} at the {leave} of road {last.road_id}", i, hint)
            via = _pick(network, last, chosen, i, hint)
            legs += _enter(network, last, via, i, hint)
            roads.append(via.road_id)
            # A turn names the connecting road; the road it leads to follows unless named next.
            after = exits(network, via.road_id, "end" if legs[-1].direction > 0 else "start")
            nxt = str(stops[i + 1]) if i + 1 < len(stops) else None
            if after and (nxt is None or nxt in TURNS):
                legs += _enter(network, legs[-1], after[0], i, hint)
                roads.append(after[0].road_id)
            i += 1
            continue
        if stop not in network.roads:
            raise RouteError(f"no road '{stop}' in {network.source_name}", i, hint)
        direct = [e for e in outs if e.road_id == stop]
        if direct:
            via = _pick(network, last, direct, i, hint)
            legs += _enter(network, last, via, i, hint)
            roads.append(stop)
            i += 1
            continue
        # Through a junction: the connecting road that leads to `stop`.
        through = [e for e in outs if e.connection is not None and not e.connection.direct
                   and any(x.road_id == stop for x in exits(network, e.road_id, _other(e.contact)))]
        if not through:
            raise RouteError(f"road {last.road_id} does not lead to road {stop}", i, hint)
        via = _pick(network, last, through, i, hint)
        legs += _enter(network, last, via, i, hint)
        inner = legs[-1]
        onward = [x for x in exits(network, via.road_id, "end" if inner.direction > 0 else "start")
                  if x.road_id == stop]
        legs += _enter(network, inner, onward[0], i, hint)
        roads += [via.road_id, stop]
        i += 1
    return roads, legs


def _start_legs(road: Road, lane: int, s_start: float, direction: int) -> list[Leg]:
    """Legs from the first road's entry end when the route lane can be traced back to
    it (so actors on one route share one station frame), else from ``s_start``'s section."""
    if not _lane_exists(road, lane, s_start):
        raise RouteError(f"road {road.id} has no lane {lane} at s = {s_start:.1f} m", 0,
                         f"lanes there: {', '.join(str(i) for i in road.lane_ids(s_start))}")
    # Trace the lane back section by section.
    secs = list(road.sections)
    k = _section_of(road, s_start)
    lane_back = lane
    while True:
        prev_k = k - 1 if direction > 0 else k + 1
        if not 0 <= prev_k < len(secs):
            break
        own = secs[k].lane(lane_back)
        linked = (own.predecessors if direction > 0 else own.successors) if own is not None else ()
        cand = [c for c in linked if secs[prev_k].lane(c) is not None]
        if not cand:
            break
        lane_back, k = cand[0], prev_k
    start = secs[k].s0 if direction > 0 else secs[k].s1
    legs = _follow_road(road, lane_back, start, direction)
    return legs


def _section_of(road: Road, s: float) -> int:
    k = 0
    for i, sec in enumerate(road.sections):
        if sec.s0 <= s:
            k = i
    return k


def _pick(network: RoadNetwork, last: Leg, options: list[_Exit], stop: int, hint: str) -> _Exit:
    """Of several ways to the same place, the one whose lane links take the route lane."""
    for e in options:
        if _entry_lane(network, last, e) is not None:
            return e
    taken = "; ".join(f"{e.road_id} from lanes {_lanes_taken(e)}" for e in options)
    raise RouteError(f"lane {last.lane} of road {last.road_id} has no connection to road {options[0].road_id}"
                     if len(options) == 1 else f"lane {last.lane} of road {last.road_id} has none of these "
                     f"connections", stop, f"{taken}; {hint}")


def _enter(network: RoadNetwork, last: Leg, ex: _Exit, stop: int, hint: str) -> list[Leg]:
    lane = _entry_lane(network, last, ex)
    if lane is None:
        raise RouteError(f"lane {last.lane} of road {last.road_id} does not continue into road {ex.road_id}",
                         stop, f"the connection takes lanes {_lanes_taken(ex)}; {hint}")
    road = network.road(ex.road_id)
    direction = 1 if ex.contact == "start" else -1
    try:
        return _follow_road(road, lane, 0.0 if direction > 0 else road.length, direction)
    except RouteError as exc:
        raise RouteError(exc.message, stop, exc.hint) from None


def _key(text: str):
    return (0, int(text), "") if text.lstrip("-").isdigit() else (1, 0, text)
