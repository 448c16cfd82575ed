"""Where an actor is among its road's lanes, as CARLA ScenarioRunner's criteria judge it
(srunner/scenariomanager/scenarioatomics/atomic_criteria.py): the boolean signals
`wrong_way(A)` (WrongLaneTest) and `off_lanes(A)` (OnSidewalkTest's active state), recorded
per sample for the actors a formula reads (`record`).

Both read the lanes of the actor's own road or route (the leg it is on), never another
road's: ScenarioRunner asks CARLA for the nearest lane of any road.
"""

from __future__ import annotations

import math

ALLOWED_TYPES = ("driving", "parking")  # OnSidewalkTest's allowed zones (carla.LaneType Driving, Parking)
SIDEWALK = "sidewalk"


def against_traffic(path, u: float, t: float) -> bool:
    """Whether the point at (`u`, `t`) of an actor's road or route (`FastRoad`, `RoutePath`)
    lies in a driving lane (the nearest lane centre) whose traffic runs against the direction
    the road or route is driven there; False in a junction (its connecting roads) and off
    the driving lanes."""
    road, _, _, direction = path.road_coords(u, t)
    if road.is_junction_road:
        return False
    lane = path.lane_at(u, t)  # (on a route in driving convention: road lane x direction)
    return lane is not None and road.travel_direction(direction * lane) != direction


def _lane_of(road, s: float, t: float) -> tuple[str, bool]:
    """(type, whether `t` lies inside it) of the lane at road coordinates (`s`, `t`): the lane
    that contains the point, else the nearest (the outermost one past the road's edge);
    lanes of type `none` are not lanes (carla.LaneType.Any leaves NONE out)."""
    # Scalar profile calls (`value_and_rate`): a few us, not numpy's ~40.
    sec = road.section_at_scalar(s)
    ds = s - sec.s0
    centre = road.offset_profile.value_and_rate(s)[0]
    best, best_d = None, math.inf
    for side, lanes in ((1, sec.left), (-1, sec.right)):  # inside out
        inner = centre
        for lane in lanes:
            outer = inner + side * lane.width.value_and_rate(ds)[0]
            lo, hi = min(inner, outer), max(inner, outer)
            if hi - lo > 1e-9 and lane.type.lower() != "none":  # (zero-width lanes do not exist there)
                d = lo - t if t < lo else t - hi if t > hi else 0.0
                if d < best_d:
                    best, best_d = lane.type.lower(), d
            inner = outer
    return (best or "none"), best_d == 0.0


def off_lanes(path, u: float, t: float, x: float, y: float, heading: float, length: float, width: float,
              was: bool) -> bool:
    """OnSidewalkTest's state at one tick for an actor whose centre is at (`u`, `t`) of its road
    or route (world `x`, `y` [m], `heading` [rad], box `length` x `width` [m]); `was`: its state
    at the tick before. Active: the centre in a sidewalk lane; or the centre in a lane neither
    driving nor parking, no corner of the box in a driving lane, and a corner in a sidewalk
    or the centre off every lane (ScenarioRunner: at half a lane width or more from the
    nearest lane's centre, which a point inside a lane never is). Off every lane beside a
    driving lane in a junction it keeps `was` (ScenarioRunner: the waypoint too far to tell)."""
    road, s, t_road, _ = path.road_coords(u, t)
    kind, inside = _lane_of(road, s, t_road)
    if kind == SIDEWALK:
        return True
    if kind in ALLOWED_TYPES:
        return was if (road.is_junction_road and not inside) else False
    c, n = math.cos(heading), math.sin(heading)
    kinds = []
    for fwd, side in ((1, -1), (1, 1), (-1, -1), (-1, 1)):
        cx = x + fwd * 0.5 * length * c - side * 0.5 * width * n
        cy = y + fwd * 0.5 * length * n + side * 0.5 * width * c
        cu, ct = path.project(cx, cy, u)
        corner_road, cs, cts, _ = path.road_coords(cu, ct)
        kinds.append(_lane_of(corner_road, cs, cts)[0])
    if "driving" in kinds:  # (ScenarioRunner's test reads `== (Driving or Parking)`: Driving only)
        return False
    if SIDEWALK in kinds:
        return True
    return not inside


def _on_road(run, name: str):
    if name == "ego":
        return run.ego_road.road, run.ego_s, run.ego_t, run.ego_plan.length_m, run.ego_plan.width_m
    a = run.agent_by_name[name]
    return run.agent_roads[name].road, a.s, a.t, a.length_m, a.width_m


def record(run, rec, k: int) -> None:
    """`wrong_way(A)` and `off_lanes(A)` at sample k (+1 holds, -1 not) for the actors a
    formula reads them of, from the row just recorded (`phases.record`)."""
    for name, marks in rec.wrong_ways.items():
        path, u, t, _, _ = _on_road(run, name)
        off_map = name == "ego" and run.left_road
        marks[k] = 1.0 if not off_map and against_traffic(path, u, t) else -1.0
    for name, marks in rec.offs.items():
        path, u, t, length, width = _on_road(run, name)
        x, y, heading = rec.rec[name]["x"][k], rec.rec[name]["y"][k], rec.rec[name]["heading"][k]
        was = k > 0 and marks[k - 1] > 0
        marks[k] = 1.0 if off_lanes(path, u, t, x, y, heading, length, width, was) else -1.0
