"""The road an actor drives on: a plain road driven along +s (`ActorRoad`) or a path (a
route, or a lane driven against s: `ActorPath`), as sampled fast views, and what the
twin derives from it once per run (junction legs, a plain road as a route leg)."""

from __future__ import annotations

from dataclasses import dataclass

from addt_dsl.runtime.fastroad import FastRoad
from addt_dsl.runtime.path import RoutePath
from addt_dsl.runtime.roadmesh import Elevation


class ActorRoad:
    """The road an actor drives on, as a sampled fast view."""

    def __init__(self, network, road_id: str, cache: dict):
        self.network = network
        key = (id(network), road_id)
        if key not in cache:
            cache[key] = (FastRoad(network.road(road_id)), Elevation(network.road(road_id)))
        self.road, self.elevation = cache[key]
        self.road_id = road_id

    def pose(self, s: float, t: float) -> tuple[float, float, float]:
        return self.road.point(s, t)

    def station(self, road_id: str, s: float) -> float:
        return s

    def placement(self, road_id: str, s: float) -> tuple[float, int]:
        """(station [m], direction) of a place declared on `road_id` at its station `s`."""
        return s, 1

    def direction(self, u: float) -> int:
        return 1


class ActorPath(ActorRoad):
    """An actor's route (or a lane driven against s) as one road: `runtime.path.RoutePath`."""

    def __init__(self, network, scenario_road: str, legs, cache: dict):
        self.network = network
        roads = {}
        for leg in legs:
            key = (id(network), leg.road_id)
            if key not in cache:
                cache[key] = (FastRoad(network.road(leg.road_id)), Elevation(network.road(leg.road_id)))
            roads[leg.road_id] = cache[key]
        key = scenario_road + ":" + ";".join(f"{g.road_id}{g.direction:+d}{g.lane}@{g.s_from:g}" for g in legs)
        self.road = RoutePath(key, legs, roads)
        self.elevation = self.road.elevation
        self.road_id = key

    def station(self, road_id: str, s: float) -> float:
        return self.road.station(road_id, s)

    def placement(self, road_id: str, s: float) -> tuple[float, int]:
        return self.road.placement(road_id, s)

    def direction(self, u: float) -> int:
        return self.road.direction(u)


def junction_legs(road: ActorRoad) -> list[tuple[float, float, float, float]]:
    """(entry, exit station [m], conflict point x, y [m]) of each junction leg of a path."""
    if not isinstance(road, ActorPath):
        return []
    out = []
    for leg in road.road.legs:
        r = road.network.road(leg.road_id)
        if r.junction in ("", "-1"):
            continue
        x, y, _ = r.lane_center(leg.lane, 0.5 * (leg.s_from + leg.s_to))
        out.append((road.station(leg.road_id, leg.s_from), road.station(leg.road_id, leg.s_to), float(x), float(y)))
    return out


@dataclass(frozen=True)
class PlainLeg:
    """A road driven along +s from end to end, as a route leg (`stations_on`)."""

    road_id: str
    direction: int
    s_from: float
    s_to: float
    lane: int
