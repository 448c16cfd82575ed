"""A route as one drivable road: the loop's view of an actor's path through a network.

`RoutePath` strings a route's legs (`runtime.road.route.Leg`: road, direction, s-range,
route lane) into one station `u` [m] that grows in the driving direction, and answers
the queries the loop, the behaviours and the stack ask of a road (`FastRoad`'s
interface: `reference_pose`, `point`, `project`, `curvature`, `driving_lane_ids`,
`lane_center_t`, `lane_at`, `lane_offset`, `road_band_t`, `length`). So agents, IDM,
lane changes and the ego's planner and controller drive a route as they drive a road.

Frame: the path's reference line is the centre of the route lane (t = 0 there, left of
the driving direction positive), so an actor keeping t = 0 follows its lane through lane
sections, renumbered lanes and junctions. Lane ids on a path are in *driving
convention*: road lane id × direction, so the route lane and the lanes beside it are
negative (right-hand traffic) whichever way the road runs, and "the lane to the left"
means the driver's left. `u` advances with the road station (|ds|), as `s` does on a road.

A road without a route, driven along +s, keeps the plain `FastRoad` (bit-identical runs);
everything else (a route, or a lane driven against s) is a `RoutePath`. Pure Python on
per-road samples (`FastRoad`), a few µs per query.
"""

from __future__ import annotations

import bisect
import math

class _Seg:
    __slots__ = ("fast", "elevation", "road_id", "dir", "s_from", "s_to", "u0", "u1", "lane", "h_shift",
                 "blend_t", "blend_m")

    def __init__(self, fast, elevation, leg, u0: float, h_shift: float):
        self.fast, self.elevation = fast, elevation
        self.road_id, self.dir, self.lane = leg.road_id, int(leg.direction), int(leg.lane)
        self.s_from, self.s_to = float(leg.s_from), float(leg.s_to)
        self.u0, self.u1 = u0, u0 + abs(self.s_to - self.s_from)
        self.h_shift = h_shift  # added to the road heading: pi against s, plus 2 pi k (unwrap)
        # Where the route lane continues in a lane beside it (a merge lane ends, a lane with no
        # link), the reference moves across smoothly: offset [m, road t] at entry, over [m].
        self.blend_t, self.blend_m = 0.0, 0.0


class RoutePath:
    """The legs of one route as a single road-like object (see the module doc)."""

    def __init__(self, key: str, legs, roads: dict):
        """`roads`: road id → (FastRoad, Elevation) of every road the legs use."""
        self.key = key
        self.legs = tuple(legs)
        segs: list[_Seg] = []
        u = 0.0
        prev_h = None
        for leg in self.legs:
            fast, elev = roads[leg.road_id]
            h = fast.reference_pose(leg.s_from)[2] + (math.pi if leg.direction < 0 else 0.0)
            shift = math.pi if leg.direction < 0 else 0.0
            if prev_h is not None:  # keep the heading continuous across legs
                shift += math.tau * round((prev_h - h) / math.tau)
            seg = _Seg(fast, elev, leg, u, shift)
            if segs:
                _blend(segs[-1], seg)
            segs.append(seg)
            u = seg.u1
            prev_h = fast.reference_pose(leg.s_to)[2] + seg.h_shift
        self._segs = segs
        self._u0 = [sg.u0 for sg in segs]
        self.length = u
        self._last = 0
        self.elevation = _PathElevation(self)

    # ---- legs
    def _seg(self, u: float) -> _Seg:
        segs, k = self._segs, self._last
        sg = segs[k]
        if not (sg.u0 <= u < sg.u1):
            k = max(0, bisect.bisect_right(self._u0, u) - 1)
            self._last = k
            sg = segs[k]
        return sg

    @staticmethod
    def _s(sg: _Seg, u: float) -> float:
        return sg.s_from + sg.dir * (u - sg.u0)

    @staticmethod
    def _lc(sg: _Seg, s: float) -> float:
        """Road t of the path's reference line: the route lane's centre (blended after a shift)."""
        t = sg.fast.lane_center_t(sg.lane, s)
        if sg.blend_m:
            x = sg.dir * (s - sg.s_from) / sg.blend_m
            if x < 1.0:
                x = 0.0 if x < 0.0 else x
                t += sg.blend_t * (1.0 - x * x * (3.0 - 2.0 * x))
        return t

    def road_at(self, u: float) -> tuple[str, float, int]:
        """(road id, road station [m], direction) at path station `u`."""
        sg = self._seg(u)
        return sg.road_id, self._s(sg, u), sg.dir

    def direction(self, u: float) -> int:
        return self._seg(u).dir

    def station(self, road_id: str, s: float) -> float:
        """Path station [m] of road station `s` on the first leg on `road_id` that holds it."""
        for sg in self._segs:
            lo, hi = (sg.s_from, sg.s_to) if sg.dir > 0 else (sg.s_to, sg.s_from)
            if sg.road_id == road_id and lo - 1e-9 <= s <= hi + 1e-9:
                return sg.u0 + sg.dir * (s - sg.s_from)
        raise ValueError(f"road {road_id} at s = {s:g} m is not on route {self.key}")

    # ---- reference line (the route lane's centre)
    def reference_pose(self, u: float) -> tuple[float, float, float]:
        sg = self._seg(u)
        s = self._s(sg, u)
        x, y, h = sg.fast.point(s, self._lc(sg, s))
        return x, y, h + sg.h_shift

    def curvature(self, u: float) -> float:
        sg = self._seg(u)
        s = self._s(sg, u)
        k = sg.dir * sg.fast.curvature(s)
        t = sg.dir * self._lc(sg, s)
        return k / max(0.2, 1.0 - k * t)

    def point(self, u: float, t: float) -> tuple[float, float, float]:
        sg = self._seg(u)
        s = self._s(sg, u)
        x, y, h = sg.fast.point(s, self._lc(sg, s) + sg.dir * t)
        return x, y, h + sg.h_shift

    def project(self, x: float, y: float, hint: float | None = None) -> tuple[float, float]:
        """(u, t) of a point; `hint` (a nearby u) makes it a local search."""
        segs = self._segs
        if hint is None:
            k = self._nearest_seg(x, y)
            sg = segs[k]
            s_hint = None
        else:
            sg = self._seg(hint)
            k = self._last
            s_hint = self._s(sg, hint)
        for _ in range(len(segs) + 1):
            s, t_road = sg.fast.project(x, y, s_hint)
            rx, ry, h = sg.fast.reference_pose(s)
            along = (x - rx) * math.cos(h) + (y - ry) * math.sin(h)  # beyond the road's end
            u = sg.u0 + sg.dir * (s + along - sg.s_from)
            if u < sg.u0 - 1e-6 and k > 0:
                k -= 1
            elif u > sg.u1 + 1e-6 and k < len(segs) - 1:
                k += 1
            else:
                break
            nxt = segs[k]
            # Moving to a neighbour leg: start from its end that touches this one.
            s_hint = nxt.s_to if nxt.u1 <= sg.u0 else nxt.s_from
            sg = nxt
        s_c = min(max(s, 0.0), sg.fast.length)
        t = sg.dir * (t_road - self._lc(sg, s_c))
        return u, t

    def _nearest_seg(self, x: float, y: float) -> int:
        best, best_d = 0, math.inf
        for k, sg in enumerate(self._segs):
            dd = sg.fast.nearest_d2(x, y, min(sg.s_from, sg.s_to), max(sg.s_from, sg.s_to))
            if dd < best_d:
                best, best_d = k, dd
        return best

    # ---- lanes (driving convention: road lane id x direction)
    def driving_lane_ids(self, u: float) -> tuple[int, ...]:
        sg = self._seg(u)
        ids = sg.fast.driving_lane_ids(self._s(sg, u))
        return tuple(sg.dir * i for i in ids) if sg.dir > 0 else tuple(sg.dir * i for i in reversed(ids))

    def lane_center_t(self, lane: int, u: float) -> float:
        sg = self._seg(u)
        s = self._s(sg, u)
        return sg.dir * (sg.fast.lane_center_t(sg.dir * lane, s) - self._lc(sg, s))

    def lane_at(self, u: float, t: float) -> int | None:
        best, best_d = None, math.inf
        for lane in self.driving_lane_ids(u):
            d = abs(t - self.lane_center_t(lane, u))
            if d < best_d:
                best, best_d = lane, d
        return best

    def lane_offset(self, u: float, t: float) -> float:
        lane = self.lane_at(u, t)
        return t if lane is None else t - self.lane_center_t(lane, u)

    def road_band_t(self, u: float) -> tuple[float, float]:
        sg = self._seg(u)
        s = min(max(self._s(sg, u), 0.0), sg.fast.length)
        lo, hi = sg.fast.road_band_t(s)
        lc = self._lc(sg, s)
        a, b = sg.dir * (lo - lc), sg.dir * (hi - lc)
        return (a, b) if a <= b else (b, a)


def _blend(prev: _Seg, seg: _Seg) -> None:
    """Set `seg`'s blend where the route lane's centre does not continue where `prev`'s ended."""
    x, y, _ = prev.fast.point(prev.s_to, RoutePath._lc(prev, prev.s_to))
    s_in = seg.s_from
    rx, ry, h = seg.fast.reference_pose(s_in)
    t_in = -(x - rx) * math.sin(h) + (y - ry) * math.cos(h)
    jump = t_in - seg.fast.lane_center_t(seg.lane, s_in)
    if abs(jump) > 0.05:
        seg.blend_t = jump
        seg.blend_m = min(max(10.0, 12.0 * abs(jump)), seg.u1 - seg.u0)


class _PathElevation:
    """z [m] and grade along the path [-] (the road's grade, signed by the direction)."""

    def __init__(self, path: RoutePath):
        self.path = path
        self.flat = all(sg.elevation.flat for sg in path._segs)

    def at(self, u: float) -> tuple[float, float]:
        if self.flat:
            return 0.0, 0.0
        sg = self.path._seg(u)
        z, grade = sg.elevation.at(RoutePath._s(sg, u))
        return z, sg.dir * grade
