"""A route as one drivable road: the loop's view of an actor's path through a network.

`RoutePath` strings a route's legs (`addt_dsl.road.route.Leg`: road, direction, s-range,
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

import numpy as np

from addt_dsl.runtime.fastroad import MIN_GROUND_SCALE, STEP_M, FastRoad

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


class RoutePath(FastRoad):
    """The legs of one route as a single road-like object (see the module doc).

    It is a `FastRoad` whose sampled line is the route lane's centre over `u` (sampled once,
    vectorised, every `STEP_M`), so poses, curvature and projections cost what they cost on a
    road; lane queries go to the leg's road."""

    def __init__(self, key: str, legs, roads: dict):  # noqa: D107 - FastRoad's samples, set here
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
        self._lanes_memo: dict = {}
        self._sample(max(u, 1e-3))
        self.elevation = _PathElevation(self)

    def _sample(self, length: float) -> None:
        """The lane-centre line over u: FastRoad's sample arrays (x, y, heading, curvature).
        Lane queries go to the leg's road (`_reference_t`): samples straddle legs."""
        n = max(2, int(math.ceil(length / STEP_M)) + 1)
        u = np.linspace(0.0, length, n)
        idx = np.clip(np.searchsorted(self._u0, u, side="right") - 1, 0, len(self._segs) - 1)
        x, y, h, k, g = (np.empty(n) for _ in range(5))
        for i, sg in enumerate(self._segs):
            m = idx == i
            if not np.any(m):
                continue
            s = np.clip(sg.s_from + sg.dir * (u[m] - sg.u0), 0.0, sg.fast.length)
            t = sg.fast.lane_center_t_array(sg.lane, s)
            if sg.blend_m:
                f = np.clip(sg.dir * (s - sg.s_from) / sg.blend_m, 0.0, 1.0)
                t = t + sg.blend_t * (1.0 - f * f * (3.0 - 2.0 * f))
            x[m], y[m], hh, kk = sg.fast.sample_arrays(s, t)
            h[m] = hh + sg.h_shift
            kd = sg.dir * kk  # reference curvature as driven; the lane centre's, at its offset
            g[m] = np.maximum(0.2, 1.0 - kd * sg.dir * t)  # the lane centre's length per metre of u
            k[m] = kd / g[m]
        self._s = u.tolist()
        self._x, self._y = x.tolist(), y.tolist()
        self._h = np.unwrap(h).tolist()
        self._k = k.tolist()
        self._g = g.tolist()
        self._xy = np.stack([x, y], axis=1)
        self._table()

    def ground_scale(self, s: float, t: float) -> float:
        """`FastRoad.ground_scale` on a path: `u` advances with the road's station, so the
        ground per metre of `u` at offset `t` from the lane centre is the lane centre's
        (1 - kappa_ref * t_centre) times the offset factor on the lane centre's curvature."""
        if s > self.length or s < 0.0:
            return 1.0
        i, u = self._index(s)
        ks, gs = self._k, self._g
        g = (gs[i] + u * (gs[i + 1] - gs[i])) * (1.0 - (ks[i] + u * (ks[i + 1] - ks[i])) * t)
        return g if g > MIN_GROUND_SCALE else MIN_GROUND_SCALE

    # ---- legs
    def _seg(self, u: float) -> _Seg:
        segs, k = self._segs, self._last
        sg = segs[k]
        if not (sg.u0 <= u < sg.u1):
            k = max(0, bisect.bisect_right(self._u0, u) - 1)
            self._last = k
            sg = segs[k]
        return sg

    def road_at(self, u: float) -> tuple[str, float, int]:
        """(road id, road station [m], direction) at path station `u`."""
        sg = self._seg(u)
        return sg.road_id, sg.s_from + sg.dir * (u - sg.u0), sg.dir

    def direction(self, u: float) -> int:
        return self._seg(u).dir

    def station(self, road_id: str, s: float) -> float:
        """Path station [m] of road station `s` on the first leg on `road_id` that holds it
        (else continued from the first leg on that road)."""
        return self.placement(road_id, s)[0]

    def placement(self, road_id: str, s: float) -> tuple[float, int]:
        """(`station`, the direction of the leg that holds it): at a leg's end the path's
        station is the next leg's start, whose direction may differ (a lane driven against
        its road's s, then a connecting road along its own)."""
        first = None
        for sg in self._segs:
            if sg.road_id != road_id:
                continue
            lo, hi = (sg.s_from, sg.s_to) if sg.dir > 0 else (sg.s_to, sg.s_from)
            if lo - 1e-9 <= s <= hi + 1e-9:
                return sg.u0 + sg.dir * (s - sg.s_from), sg.dir
            first = first or sg
        if first is None:
            raise ValueError(f"road {road_id} is not on route {self.key}")
        return first.u0 + first.dir * (s - first.s_from), first.dir

    def speed_limit(self, u: float) -> float | None:
        """The map's speed limit [m/s] of the leg at path station `u` [m] (None where it gives none)."""
        sg = self._seg(u)
        return sg.fast.speed_limit(sg.s_from + sg.dir * (u - sg.u0))

    # ---- lanes (driving convention: road lane id x direction)
    def driving_lane_ids(self, u: float) -> tuple[int, ...]:
        sg = self._seg(u)
        ids = sg.fast.driving_lane_ids(sg.s_from + sg.dir * (u - sg.u0))
        key = (id(sg), ids)
        out = self._lanes_memo.get(key)
        if out is None:
            out = tuple(sg.dir * i for i in (ids if sg.dir > 0 else reversed(ids)))
            self._lanes_memo[key] = out
        return out

    def road_coords(self, u: float, t: float):
        """`FastRoad.road_coords` of path coordinates: the leg's road, station and t, and
        the leg's direction (-1: driven against s)."""
        sg = self._seg(u)
        s = min(max(sg.s_from + sg.dir * (u - sg.u0), 0.0), sg.fast.length)
        return sg.fast.road, s, _reference_t(sg, s) + sg.dir * t, sg.dir

    def lane_center_t(self, lane: int, u: float) -> float:
        sg = self._seg(u)
        s = sg.s_from + sg.dir * (u - sg.u0)
        return sg.dir * (sg.fast.lane_center_t(sg.dir * lane, s) - _reference_t(sg, s))

    def _nearest_lane(self, u: float, t: float) -> tuple[int | None, float]:
        """(lane, its centre's t) nearest to path offset `t` at `u`."""
        lanes = self.driving_lane_ids(u)
        sg = self._segs[self._last]
        s = sg.s_from + sg.dir * (u - sg.u0)
        ref = _reference_t(sg, s)
        fast, d = sg.fast, sg.dir
        best, best_c, best_d = None, t, math.inf
        for lane in lanes:
            c = d * (fast.lane_center_t(d * lane, s) - ref)
            dist = abs(t - c)
            if dist < best_d:
                best, best_c, best_d = lane, c, dist
        return best, best_c

    def lane_at(self, u: float, t: float) -> int | None:
        return self._nearest_lane(u, t)[0]

    def lane_offset(self, u: float, t: float) -> float:
        lane, centre = self._nearest_lane(u, t)
        return t if lane is None else t - centre

    def road_band_t(self, u: float, paved: bool = False) -> tuple[float, float]:
        sg = self._seg(u)
        s = min(max(sg.s_from + sg.dir * (u - sg.u0), 0.0), sg.fast.length)
        lo, hi = sg.fast.paved_band_t(s) if paved else sg.fast.road_band_t(s)
        ref = _reference_t(sg, s)
        a, b = sg.dir * (lo - ref), sg.dir * (hi - ref)
        return (a, b) if a <= b else (b, a)


    def paved_band_t(self, u: float) -> tuple[float, float]:
        return self.road_band_t(u, paved=True)


def _reference_t(sg: _Seg, s: float) -> float:
    """Road t of the path's reference line: the route lane's centre (blended after a shift)."""
    t = sg.fast.lane_center_t(sg.lane, s)
    if sg.blend_m:
        x = sg.dir * (s - sg.s_from) / sg.blend_m
        if x < 1.0:
            x = 0.0 if x < 0.0 else x
            t += sg.blend_t * (1.0 - x * x * (3.0 - 2.0 * x))
    return t


def _blend(prev: _Seg, seg: _Seg) -> None:
    """Set `seg`'s blend where the route lane's centre does not continue where `prev`'s ended."""
    x, y, _ = prev.fast.point(prev.s_to, _reference_t(prev, prev.s_to))
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
        z, grade = sg.elevation.at(sg.s_from + sg.dir * (u - sg.u0))
        return z, sg.dir * grade
