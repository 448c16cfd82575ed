"""Positions (lane, road, world, relative, route), routes and trajectory shapes (clothoids, NURBS)."""

import math
from dataclasses import dataclass

from addt_dsl import expr as E
from addt_dsl import units
from addt_dsl.expr import eval_param_expr
from addt_dsl.interop.openscenario.params import plus_expr
from addt_dsl.interop.openscenario.registry import POSITIONS
from addt_dsl.interop.openscenario.xml import Stop, first_of, only_child
from addt_dsl.road.route import RouteError, exits, resolve_route, turn_of

MAX_STATION_M = 1e6  # a road station beyond this is refused as content, not translated [m]
MAX_LANE_ID = 100


# ---------------------------------------------------------------- the document

def lane_ids_at(odr, s: float) -> tuple[int, ...]:
    """Every lane id of a road's lane section at s (driving or not)."""
    try:
        return tuple(odr.lane_ids(s))
    except ValueError:
        return ()


def bspline_basis(knots: list[float], order: int, n: int, u: float) -> list[float]:
    """The n B-spline basis functions of `order` (degree order - 1) at `u` (Cox-de Boor)."""
    basis = [1.0 if knots[i] <= u < knots[i + 1] else 0.0 for i in range(len(knots) - 1)]
    for k in range(2, order + 1):
        nxt = []
        for i in range(len(knots) - k):
            left = right = 0.0
            if knots[i + k - 1] > knots[i]:
                left = (u - knots[i]) / (knots[i + k - 1] - knots[i]) * basis[i]
            if knots[i + k] > knots[i + 1]:
                right = (knots[i + k] - u) / (knots[i + k] - knots[i + 1]) * basis[i + 1]
            nxt.append(left + right)
        basis = nxt
    return basis[:n]

for _name, _note in (
        ("RelativeWorldPosition", "the language places actors on lanes; a world offset from another entity is "
                                  "not read"),
        ("RelativeObjectPosition", "the language places actors on lanes; an offset in another entity's frame is "
                                   "not read"),
        ("GeoPosition", "the twin has no geodetic reference"),
        ("TrajectoryPosition", "a position along a trajectory is not read"),
):
    POSITIONS.declare(_name, "refused", _note)


@dataclass(frozen=True)
class Placement:
    """A place on a lane: the plan's road name, the lane id, the station s [m] and the offset from
    the lane's centre [m] (to the left of +s), s and offset as expressions (parameters stay)."""
    road: str
    lane: int
    s: E.Expr
    offset: E.Expr


class Positions:
    # -- positions

    def position(self, pos_el, who: str):
        """Where the position is (a Placement), or None after a diagnostic."""
        pos = only_child(pos_el)
        if pos is None:
            self.error(pos_el, "a <Position> holds one position")
            return None
        translate = POSITIONS.translator(pos.tag)
        if translate is not None:
            self.level_body(pos, who)
            return translate(self, pos, who)
        self.skip(pos, f"<{pos.tag}> is not translated: {who} starts at the start of the first road",
                  "lane, road, world and relative road/lane positions are translated")
        return None

    def level_body(self, pos, who: str) -> None:
        """W0802 for a pitch or roll (a WorldPosition's `p`/`r`, an Orientation's) other than 0:
        the twin poses bodies level across the road and along its grade."""
        orient = pos if pos.tag == "WorldPosition" else pos.find("Orientation")
        if orient is None:
            return
        tilted = [f"{name} {self.value(orient, attr):g} rad" for attr, name in (("p", "pitch"), ("r", "roll"))
                  if orient.get(attr) is not None and self.value(orient, attr) != 0.0]
        if tilted:
            self.approx(orient, f"{' and '.join(tilted)} of {who}: not modelled (the body stays level across the road "
                                "and follows its grade)")

    @POSITIONS.register("LanePosition", "exact", "road, lane, s and offset (parameters stay parameters); an "
                        "Orientation's h as the body's `yaw` (pitch and roll other than 0: W0802)")
    def lane_position(self, pos, who: str):
        road = self.road(self.raw(pos, "roadId"), pos)
        lane = int(self.value(pos, "laneId"))
        s = self.number(pos, "s", units.LENGTH)
        odr = self.network.road(next(i for i, r in self.roads.items() if r.name == road))
        s_val = float(eval_param_expr(s, self.param_values()))
        if not math.isfinite(s_val) or abs(s_val) > MAX_STATION_M or abs(lane) > MAX_LANE_ID:
            self.error(pos, f"s = {s_val:g} m, lane {lane}: not a place on any road "
                            f"(|s| at most {MAX_STATION_M:g} m, |laneId| at most {MAX_LANE_ID})")
            raise Stop
        if 0.0 <= s_val <= odr.length + 1e-6 and lane not in lane_ids_at(odr, s_val):
            self.error(pos, f"road {odr.id} has no lane {lane} at s = {s_val:g} m",
                       f"lanes there: {', '.join(str(i) for i in lane_ids_at(odr, s_val))}")
            raise Stop
        return Placement(road, lane, s, self.mirror(self.number(pos, "offset", units.LENGTH, 0.0)))

    @POSITIONS.register("RoadPosition", "exact", "the lane at (s, t) and the offset from its centre")
    @POSITIONS.register("WorldPosition", "approx", "the lane of the nearest road at (x, y) facing h (a point off "
                        "every road: the nearest reference line); h as the body's `yaw` to that lane")
    @POSITIONS.register("RelativeRoadPosition", "exact", "relative to an entity placed before it")
    @POSITIONS.register("RelativeLanePosition", "exact", "relative to an entity placed before it (dLane, ds)")
    def position_from_road(self, pos, who):
        if pos.tag == "RoadPosition":
            road_id, s, t = self.raw(pos, "roadId"), self.value(pos, "s"), self.mirror(self.value(pos, "t"))
        elif pos.tag == "WorldPosition":
            x, y = self.value(pos, "x"), self.mirror(self.value(pos, "y"))
            h = self.mirror(self.value(pos, "h")) if pos.get("h") is not None else None
            road_id, s, t = self.world_to_road(x, y, h)
        else:
            ref = self.actor_name(pos)
            if ref is None or ref not in self.placed:
                self.error(pos, f"{pos.tag} relative to '{pos.get('entityRef')}', which has no position yet")
                return None
            ref_at = self.placed[ref]
            road_name, lane, s_ref, off_ref = ref_at.road, ref_at.lane, ref_at.s, ref_at.offset
            params = self.param_values()
            road_id = next(i for i, r in self.roads.items() if r.name == road_name)
            if pos.tag == "RelativeLanePosition":
                d_lane = int(self.value(pos, "dLane"))
                new_lane = lane + d_lane
                if lane * new_lane <= 0 and d_lane:  # lane 0 is the reference line
                    new_lane += 1 if d_lane > 0 else -1
                ds = self.number(pos, "ds", units.LENGTH, 0.0)
                return Placement(road_name, new_lane, plus_expr(s_ref, ds),
                                 self.mirror(self.number(pos, "offset", units.LENGTH, 0.0)))
            road = self.network.road(road_id)
            s = eval_param_expr(s_ref, params) + self.value(pos, "ds")
            t = road.lane_center_t(lane, eval_param_expr(s_ref, params)) + eval_param_expr(off_ref, params) \
                + self.mirror(self.value(pos, "dt"))
        road_name = self.road(str(road_id), pos)
        odr = self.network.road(str(road_id))
        lane = odr.lane_at(s, t)
        if lane is None:
            self.error(pos, f"{who}: no lane at s={s:g} m, t={t:g} m of road {road_id}")
            return None
        offset = t - odr.lane_center_t(lane, s)
        return Placement(road_name, lane, E.Num(value=round(s, 9)), E.Num(value=round(offset, 9)))

    def world_to_road(self, x: float, y: float, h: float | None) -> tuple[str, float, float]:
        """(road id, s, t) of world point (x, y) [m]: among the roads with a lane there (the
        point alongside the road, not beyond an end), those whose lane is driven the way `h`
        [rad] faces first, then roads outside junctions (a junction's connecting roads overlap
        each other and the roads they join), then the least offset from the lane's centre.
        Without any such road: the road whose reference line is nearest."""
        best, nearest = None, None
        for rid in self.network.roads:
            road = self.network.road(rid)
            s, t = road.project(x, y)
            px, py = (float(v) for v in road.point_at(s, t))
            if nearest is None or abs(t) < abs(nearest[2]):
                nearest = (rid, s, t)
            lane = road.lane_at(s, t) if math.hypot(px - x, py - y) < 0.5 else None
            if lane is None:
                continue
            against = False
            if h is not None:
                lane_h = float(road.reference_pose(s)[2]) + (0.0 if road.travel_direction(lane) > 0 else math.pi)
                against = math.cos(h - lane_h) < 0
            key = (against, road.is_junction_road, abs(t - float(road.lane_center_t(lane, s))))
            if best is None or key < best[0]:
                best = (key, (rid, s, t))
        return best[1] if best is not None else nearest

    def route_element(self, ref_parent):
        """The <Route> of an AssignRouteAction or a RouteRef: inline, or a route catalog's
        entry (its parameters as the reference assigns them are not read); None after a
        diagnostic."""
        inline = ref_parent.find("Route")
        if inline is not None:
            return inline
        ref = ref_parent.find("CatalogReference")
        if ref is None:
            self.error(ref_parent, f"<{ref_parent.tag}> needs a <Route> or a <CatalogReference>")
            return None
        return self.catalog_entry(ref, kinds=("Route",))

    @POSITIONS.register("RoutePosition", "approx", "from lane coordinates on a route of lane or road "
                        "positions; other in-route positions refused")
    def route_position(self, pos, who: str):
        """A RoutePosition `FromLaneCoordinates`: `pathS` along the route from its first
        waypoint, in `laneId` there. Placed on the route's first road (the language counts
        `at S` along the route from its entry end), in the first-road lane whose route leg
        is `laneId` where the point is; the route becomes the actor's when nothing assigns
        one. (road, lane, s, offset) or None after a diagnostic."""
        route_el = self.route_element(first_of(pos.find("RouteRef"), pos))
        lane_coords = pos.find("InRoutePosition/FromLaneCoordinates")
        if route_el is None or lane_coords is None:
            if route_el is not None:
                self.skip(first_of(only_child(pos.find("InRoutePosition")) if pos.find("InRoutePosition") is not None
                                 else None, pos), "a route position is translated from lane coordinates only")
            return None
        path_s, lane_id = self.value(lane_coords, "pathS", units.LENGTH), int(self.value(lane_coords, "laneId"))
        offset = self.mirror(self.number(lane_coords, "laneOffset", units.LENGTH, 0.0))
        first_wp = route_el.find("Waypoint/Position/LanePosition")
        stops = []
        for wp in route_el.iterfind("Waypoint/Position/*"):
            if wp.get("roadId") is None:
                self.skip(wp, "a waypoint that is not a lane or road position: the route position is not translated")
                return None
            if not stops or stops[-1] != self.resolve(wp.get("roadId")):
                stops.append(self.resolve(wp.get("roadId")))
        if first_wp is None or not stops or path_s < 0:
            self.skip(pos, "a route position needs a route that starts at a lane position and pathS >= 0")
            return None
        road_name = self.road(stops[0], first_wp)
        odr = self.network.road(stops[0])
        s_wp = self.value(first_wp, "s", units.LENGTH)
        candidates = sorted(odr.driving_lane_ids(min(max(s_wp, 0.0), odr.length)), key=lambda i: (i != lane_id, abs(i)))
        for lane in candidates:
            try:
                _, legs = resolve_route(self.network, stops, lane, None)
            except RouteError:
                continue
            u = abs(s_wp - legs[0].s_from) + path_s  # from the first road's entry end
            at, done = legs[-1], 0.0
            for leg in legs:
                if u <= done + abs(leg.s_to - leg.s_from) + 1e-9:
                    at = leg
                    break
                done += abs(leg.s_to - leg.s_from)
            if at.lane == lane_id:
                break
        else:
            self.skip(pos, f"no lane of road {stops[0]} leads along the route to lane {lane_id} at pathS "
                           f"{path_s:g} m: not translated")
            return None
        s_road = s_wp + legs[0].direction * path_s  # a station on the first road, or its continuation
        self.actors.get(who, {}).setdefault("route_from_position", route_el)
        return Placement(road_name, lane, E.Num(value=round(s_road, 9)), offset)

    def file_heading(self, pos_el, placed) -> tuple[str, float] | None:
        """The heading a position gives its entity, as esmini places it (OSCPosition.cpp), in
        OpenDRIVE's frame: ("world", h) for a WorldPosition's `h` or an absolute Orientation;
        ("lane", h) relative to the lane's driving direction (a LanePosition's or
        RelativeLanePosition's relative Orientation); ("road", h) relative to the road's +s (a
        road position's relative Orientation). None: the lane's driving direction (no heading
        given)."""
        pos = only_child(pos_el) if pos_el is not None else None
        if pos is None or placed.lane == 0:
            return None
        if pos.tag == "WorldPosition":
            return ("world", self.mirror(self.value(pos, "h"))) if pos.get("h") is not None else None
        orient = pos.find("Orientation")
        if orient is None or orient.get("h") is None:
            return None
        h = self.mirror(self.value(orient, "h"))
        if orient.get("type", "relative") == "absolute":
            return "world", h
        return ("lane" if pos.tag in ("LanePosition", "RelativeLanePosition") else "road"), h

    def heading_from_lane(self, heading: tuple[str, float], placed, reverse: bool) -> float:
        """`file_heading` relative to the actor's driving direction where it is placed (its
        lane's, turned round when it drives against it) [rad], in [-pi, pi]: the language's
        `yaw`. Relative orientations stay exact; a world heading takes the road's exact
        reference heading at the placement's station."""
        kind, h = heading
        odr = self.network.road(next(i for i, r in self.roads.items() if r.name == placed.road))
        along_s = (odr.travel_direction(placed.lane) > 0) != reverse
        if kind == "lane":
            rel = h - (math.pi if reverse else 0.0)
        elif kind == "road":
            rel = h - (0.0 if along_s else math.pi)
        else:
            s_now = min(max(float(eval_param_expr(placed.s, self.param_values())), 0.0), odr.length)
            rel = h - float(odr.reference_pose(s_now)[2]) - (0.0 if along_s else math.pi)
        return math.remainder(rel, 2.0 * math.pi)

    def against_s(self, pos_el, placed) -> bool:
        """Whether the entity faces against its lane's driving direction (addt-dsl, like
        OpenSCENARIO's default, drives an actor in its lane's direction)."""
        try:
            heading = self.file_heading(pos_el, placed)
            return heading is not None and math.cos(self.heading_from_lane(heading, placed, False)) < 0
        except (ValueError, ArithmeticError, Stop):
            return False

    def road_point(self, pos_el, who: str):
        """(s, t) of a position on the actor's road, or None after a diagnostic."""
        got = self.position(pos_el, who)
        if got is None:
            return None
        road, lane, s, offset = got.road, got.lane, got.s, got.offset
        params = self.param_values()
        road_id = next(i for i, r in self.roads.items() if r.name == road)
        if road != self.placed[who].road:
            self.approx(pos_el, f"a point on road {road_id}, not {who}'s road: its s and t are used as they are")
        s_val = float(eval_param_expr(s, params))
        odr = self.network.road(road_id)
        if not 0.0 <= s_val <= odr.length:
            # esmini's Position::SetLongitudinalTrackPos clamps s to the road (with a warning).
            clamped = min(max(s_val, 0.0), odr.length)
            self.approx(pos_el, f"a point at s = {s_val:g} m, beyond road {road_id} ({odr.length:.6g} m): "
                                f"at s = {clamped:.6g} m, the road's end, as esmini places it")
            s_val = clamped
        try:
            t_val = odr.lane_center_t(lane, s_val) + float(eval_param_expr(offset, params))
        except ValueError as exc:
            self.skip(pos_el, f"a point the road does not have: {exc}")
            return None
        return s_val, t_val

    def world_point(self, pos_el, who: str):
        """(x, y, heading) [m, m, rad] of a position, facing its lane's driving direction (or
        its `Orientation`); None after a diagnostic."""
        world = only_child(pos_el)
        if world is not None and world.tag == "WorldPosition" and world.get("h") is not None:
            # Where it says, facing where it says (a clothoid starts with that heading, not the road's).
            return self.value(world, "x"), self.mirror(self.value(world, "y")), self.mirror(self.value(world, "h"))
        got = self.position(pos_el, who)
        if got is None:
            return None
        road, lane, s, offset = got.road, got.lane, got.s, got.offset
        params = self.param_values()
        odr = self.network.road(next(i for i, r in self.roads.items() if r.name == road))
        s_val = min(max(float(eval_param_expr(s, params)), 0.0), odr.length)
        t_val = odr.lane_center_t(lane, s_val) + float(eval_param_expr(offset, params))
        x, y, h = (float(v) for v in odr.reference_pose(s_val))
        heading = h + (math.pi if lane > 0 and odr.travel_direction(lane) < 0 else 0.0)
        orient = pos_el.find(".//Orientation")
        if orient is not None and orient.get("h") is not None:
            turn = self.mirror(self.value(orient, "h"))
            heading = turn if orient.get("type") == "absolute" else heading + turn
        return x - t_val * math.sin(h), y + t_val * math.cos(h), heading

    def clothoid(self, el, who: str):
        """A clothoid (curvature k0 + k' u over its length) from its start pose, sampled
        about every 2 m; times linear in arc length from startTime to stopTime."""
        start = self.world_point(first_of(el.find("Position"), el), who)
        if start is None:
            return None
        k0 = self.mirror(self.value(el, "curvature"))  # a left turn is a right one in CARLA's frame
        rate = el.get("curvaturePrime") if el.get("curvaturePrime") is not None else el.get("curvatureDot")
        k1 = self.mirror(self.value(el, "curvaturePrime" if el.get("curvaturePrime") is not None else "curvatureDot")) \
            if rate is not None else 0.0
        length = self.value(el, "length")
        if not 0.0 < length <= 10000.0:
            self.skip(el, f"a clothoid {length:g} m long is not translated (0 to 10 km)")
            return None
        count = int(min(max(math.ceil(length / 2.0), 8), 200))
        fine = 20 * count  # heading integrated on a grid 20 times finer than the samples
        x, y, h0 = start
        points = [(x, y)]
        du = length / fine
        for i in range(1, fine + 1):
            u_mid = (i - 0.5) * du
            heading = h0 + k0 * u_mid + 0.5 * k1 * u_mid * u_mid
            x, y = x + du * math.cos(heading), y + du * math.sin(heading)
            if i % 20 == 0:
                points.append((x, y))
        times = []
        if el.get("startTime") is not None and el.get("stopTime") is not None:
            t0, t1 = self.value(el, "startTime"), self.value(el, "stopTime")
            times = [t0 + (t1 - t0) * i / count for i in range(count + 1)]
        return points, times

    def nurbs(self, el, who: str):
        """A NURBS curve (Cox-de Boor) through its control points' world positions, sampled
        at evenly spaced parameters; times by the same rational basis when every control
        point has one."""
        order = int(self.value(el, "order"))
        cps = list(el.iterfind("ControlPoint"))
        knots = [self.value(k, "value") for k in el.iterfind("Knot")]
        if order < 2 or len(cps) < order or len(knots) != len(cps) + order or \
                any(b < a for a, b in zip(knots, knots[1:])) or knots[order - 1] >= knots[len(cps)]:
            self.error(el, f"a NURBS of order {order} with {len(cps)} control points needs {len(cps) + order} "
                           f"non-decreasing knots (it has {len(knots)})")
            return None
        pts, weights, stamps = [], [], []
        for cp in cps:
            got = self.world_point(first_of(cp.find("Position"), cp), who)
            if got is None:
                return None
            pts.append(got[:2])
            weights.append(self.value(cp, "weight", default=1.0))
            stamps.append(self.value(cp, "time") if cp.get("time") is not None else None)
        lo, hi = knots[order - 1], knots[len(cps)]
        count = int(min(max(10 * len(cps), 20), 200))
        points, times = [], []
        for j in range(count + 1):
            u = lo + (hi - lo) * j / count
            basis = bspline_basis(knots, order, len(cps), min(u, hi - 1e-9 * (hi - lo)))
            w = [b * wt for b, wt in zip(basis, weights)]
            total = sum(w)
            if total <= 0.0:
                self.error(el, "a NURBS whose weights cancel")
                return None
            points.append((sum(wi * p[0] for wi, p in zip(w, pts)) / total,
                           sum(wi * p[1] for wi, p in zip(w, pts)) / total))
            if None not in stamps:
                times.append(sum(wi * t for wi, t in zip(w, stamps)) / total)
        return points, times

    def route(self, route_el, who: str, lane: int, s):
        """An AssignRouteAction's waypoints as the actor's route (road ids, connecting roads
        included) and its start station along the route; None after a diagnostic."""
        stops = []
        for wp in route_el.iterfind("Waypoint"):
            pos = only_child(wp.find("Position")) if wp.find("Position") is not None else None
            road_id = pos.get("roadId") if pos is not None else None
            if road_id is None:
                self.skip(wp, "a waypoint that is not a lane or road position: the route is not translated")
                return None
            if not stops or stops[-1] != road_id:
                stops.append(self.resolve(road_id))
        first = self.placed[who].road
        if self.roads.get(stops[0]) is None or self.roads[stops[0]].name != first:
            self.skip(route_el, f"a route that does not start on {who}'s road: not translated")
            return None
        try:
            roads, _ = resolve_route(self.network, stops, lane, None)
        except RouteError as exc:
            self.skip(route_el, f"the route is not translated: {exc}")
            return None
        return roads, s  # `at` stays the first road's station on a route too

    def straight_on(self, road_name: str, lane: int, s, reach_m: float) -> list[str] | None:
        """A route for an ego the file gives none: from its lane, on along each road's link
        and through each junction straight on, else turning to the kerb side, else the other
        way, never onto a road it already has, until `reach_m` [m] beyond its start or a
        road end with no such way on. None when it never leaves its road."""
        first = next(i for i, r in self.roads.items() if r.name == road_name)
        try:
            s0 = float(eval_param_expr(s, self.param_values()))
            roads, legs = resolve_route(self.network, [first], lane, s0)
        except (RouteError, KeyError, ValueError, ArithmeticError):
            return None
        stops = [first]
        for _ in range(64):
            if sum(abs(g.s_to - g.s_from) for g in legs) >= reach_m:
                break
            last = legs[-1]
            outs = exits(self.network, last.road_id, "end" if last.direction > 0 else "start")
            direct = [e.road_id for e in outs if e.connection is None or e.connection.direct]
            turns = {turn_of(self.network, e.road_id, e.contact) for e in outs}
            # Straight on where a junction allows it, else the turn that crosses no oncoming
            # traffic (right under right-hand traffic), else the other; never onto a road the
            # route already has (the language's routes do not repeat a road).
            kerb, far = ("right", "left") if self.network.road(last.road_id).rule == "RHT" else ("left", "right")
            options = direct[:1] if direct else [t for t in ("straight", kerb, far) if t in turns]
            for step in options:
                try:
                    more, more_legs = resolve_route(self.network, stops + [step], lane, s0)
                except RouteError:
                    continue
                if len(set(more)) == len(more):
                    break
            else:
                break
            stops, roads, legs = list(more), more, more_legs  # (a turn's road after the junction named)
        return roads if len(roads) > 1 else None
