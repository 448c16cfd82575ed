"""A sampled view of one road for the simulation loop's hot path.

`Road` (addt_dsl.road) evaluates OpenDRIVE geometry exactly but costs ~10-500 µs per
scalar call; the loop asks for poses and projections thousands of times per run. This
view samples the reference line once per run (every `STEP_M`) and answers by
interpolation in plain Python (a few µs). The interpolation error on a sample spacing
of 0.25 m is below kappa * ds^2 / 8, i.e. under 1e-4 m for curvatures up to 0.01 /m.
"""

from __future__ import annotations

import bisect
import math

import numpy as np

STEP_M = 0.25
MIN_GROUND_SCALE = 0.2  # [m/m] `ground_scale` near a bend's centre of curvature
_BLOCK = 8192  # samples evaluated at once


class FastRoad:
    _k_a: np.ndarray | None = None  # the curvature samples (and `_s_k` their stations) as arrays, made when first asked

    def __init__(self, road):
        self.road = road
        self.length = float(road.length)
        n = max(2, int(math.ceil(self.length / STEP_M)) + 1)
        s = np.linspace(0.0, self.length, n)
        # In blocks: a clothoid's pose costs (points x integration nodes) memory at once.
        blocks = [road.reference_pose(s[i:i + _BLOCK]) for i in range(0, n, _BLOCK)]
        x, y, h = (np.concatenate([b[k] for b in blocks]) for k in range(3))
        self._s = s.tolist()
        self._x = np.asarray(x, dtype=float).tolist()
        self._y = np.asarray(y, dtype=float).tolist()
        self._h = np.unwrap(np.asarray(h, dtype=float)).tolist()
        self._k = np.asarray(road.curvature(s), dtype=float).tolist()
        self._xy = np.stack([np.asarray(x, float), np.asarray(y, float)], axis=1)
        # The same samples as arrays, for `points` and `lane_offsets` (many actors at once).
        self._s_a = np.array(self._s)
        self._xyh = np.array([self._x, self._y, self._h])
        self._center_arrays: dict[tuple[int, ...], np.ndarray] = {}  # a section's lanes -> their centres
        self._ds = self._s[1] - self._s[0]
        self._last_i = len(self._s) - 2
        self._section_starts = [sec.s0 for sec in road.sections]
        self._lanes_cache: dict[int, tuple[int, ...]] = {}
        self._center_cache: dict[int, list[float]] = {}

    # ---- reference line
    def _index(self, s: float) -> tuple[int, float]:
        # Comparisons, not min/max: this runs ~50k times per run.
        ds = self._ds
        i = int(s / ds)
        if i < 0:
            i = 0
        elif i > self._last_i:
            i = self._last_i
        return i, (s - self._s[i]) / ds

    def reference_pose(self, s: float) -> tuple[float, float, float]:
        i, u = self._index(s)
        xs, ys, hs = self._x, self._y, self._h
        x = xs[i] + u * (xs[i + 1] - xs[i])
        y = ys[i] + u * (ys[i + 1] - ys[i])
        h = hs[i] + u * (hs[i + 1] - hs[i])
        if s > self.length:  # extrapolate straight past the end
            extra = s - self.length
            h = self._h[-1]
            x, y = self._x[-1] + extra * math.cos(h), self._y[-1] + extra * math.sin(h)
        elif s < 0.0:
            x, y, h = self._x[0] + s * math.cos(self._h[0]), self._y[0] + s * math.sin(self._h[0]), self._h[0]
        return x, y, h

    def _indices(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """`_index` of many finite stations: int(s / ds) clamped (clamping the quotient
        first gives the same index), and the fraction, with the same arithmetic."""
        ds = self._ds
        i = np.minimum(np.maximum(s / ds, 0.0), self._last_i).astype(np.intp)
        return i, (s - self._s_a[i]) / ds

    def points(self, s: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """`point(s, t)` of many actors, bit for bit, plus the sample index and fraction
        (`lane_offsets` takes them): the interpolation is elementwise in numpy, in the scalar
        code's order; sin and cos stay libm's (`math`: numpy's SIMD versions may differ in
        the last bit). Finite stations; those off the road's ends are posed by `point`."""
        i, u = self._indices(s)
        table = self._xyh
        lo = table[:, i]
        x, y, h = lo + u * (table[:, i + 1] - lo)
        off = np.flatnonzero((s > self.length) | (s < 0.0))
        for j in off.tolist():  # extrapolated straight: the scalar call
            x[j], y[j], h[j] = self.reference_pose(float(s[j]))
        hl = h.tolist()
        px = x - np.fromiter(map(math.sin, hl), float, len(hl)) * t
        py = y + np.fromiter(map(math.cos, hl), float, len(hl)) * t
        return px, py, h, i, u

    def lane_offsets(self, s: np.ndarray, t: np.ndarray, i: np.ndarray, u: np.ndarray) -> np.ndarray:
        """`lane_offset(s, t)` of many actors (`i`, `u`: `points`' index and fraction),
        bit for bit: the nearest driving lane's centre, the first on equal distances."""
        if len(self._section_starts) == 1:
            keys, sec = [0], None
        else:
            sec = np.maximum(np.searchsorted(self._section_starts, s, side="right") - 1, 0)
            keys = np.unique(sec).tolist()
        out = t.copy()
        for key in keys:
            rows = slice(None) if len(keys) == 1 else np.flatnonzero(sec == key)
            lanes = self._lanes_of_section(key)
            if not lanes:
                continue
            table = self._center_arrays.get(lanes)
            if table is None:
                for lane in lanes:
                    self.lane_center_t(lane, 0.0)  # fills the lane's table
                table = self._center_arrays[lanes] = np.array([self._center_cache[lane] for lane in lanes])
            ii, uu, tt = i[rows], u[rows], t[rows]
            lo = table[:, ii]
            c = lo + uu * (table[:, ii + 1] - lo)  # a row per lane
            d = np.abs(tt - c)
            d[np.isnan(d)] = np.inf  # an absent lane is never the nearest
            nearest = d.argmin(axis=0)  # the first of equal distances, as the scalar loop's `<`
            cols = np.arange(len(tt))
            found = d[nearest, cols] < np.inf
            out[rows] = np.where(found, tt - c[nearest, cols], tt)
        return out

    def curvature(self, s: float) -> float:
        i, u = self._index(s)
        return self._k[i] + u * (self._k[i + 1] - self._k[i])

    def ground_scale(self, s: float, t: float) -> float:
        """Ground covered per metre of station [m/m] by an actor at offset `t` [m]: the
        offset curve's length element, 1 - kappa * t for the reference line's curvature
        kappa (more on the outside of a bend, less on the inside), at least
        `MIN_GROUND_SCALE` (near the centre of curvature). An actor moving at `speed`
        advances its station by speed / ground_scale. Past the ends, where the line goes on
        straight, 1."""
        if s > self.length or s < 0.0:
            return 1.0
        i, u = self._index(s)
        ks = self._k
        g = 1.0 - (ks[i] + u * (ks[i + 1] - ks[i])) * t
        return g if g > MIN_GROUND_SCALE else MIN_GROUND_SCALE

    def ground_scales(self, s: np.ndarray, t: np.ndarray, i: np.ndarray, u: np.ndarray) -> np.ndarray:
        """`ground_scale` of many actors (`i`, `u`: `points`' index and fraction), bit for bit."""
        if self._k_a is None:
            self._k_a = np.array(self._k)
            self._s_k = np.array(self._s)
        lo = self._k_a[i]
        g = 1.0 - (lo + u * (self._k_a[i + 1] - lo)) * t
        g = np.where(g > MIN_GROUND_SCALE, g, MIN_GROUND_SCALE)
        return np.where((s > self.length) | (s < 0.0), 1.0, g)

    def curvature_ahead(self, s: float, distance: float) -> tuple[np.ndarray, np.ndarray]:
        """(distance past `s` [m], curvature [1/m]) of the line's samples from `s` to `s +
        distance` (clipped to the line): what a speed plan for the curves ahead reads."""
        if self._k_a is None:  # (a RoutePath sets the sample lists itself)
            self._k_a = np.array(self._k)
            self._s_k = np.array(self._s)
        ds = self._ds
        i0 = min(max(int(s / ds), 0), self._last_i)
        i1 = min(max(int((s + distance) / ds) + 2, i0 + 1), len(self._s))
        return np.maximum(self._s_k[i0:i1] - s, 0.0), self._k_a[i0:i1]

    def point(self, s: float, t: float) -> tuple[float, float, float]:
        x, y, h = self.reference_pose(s)
        return x - math.sin(h) * t, y + math.cos(h) * t, h

    def project(self, x: float, y: float, hint: float | None = None) -> tuple[float, float]:
        """(s, t) of a point; `hint` (a nearby s) makes it a local search of a few µs."""
        if hint is None:
            d = self._xy - (x, y)
            s = self._s[int(np.argmin(np.einsum("ij,ij->i", d, d)))]
        else:
            s = hint
        length = self.length
        for _ in range(3):
            rx, ry, h = self.reference_pose(s)
            ds = (x - rx) * math.cos(h) + (y - ry) * math.sin(h)
            s += ds
            if s < 0.0:  # min(max(s, 0), length), without the calls
                s = 0.0
            elif s > length:
                s = length
            if abs(ds) < 1e-6:
                break
        rx, ry, h = self.reference_pose(s)
        t = -(x - rx) * math.sin(h) + (y - ry) * math.cos(h)
        return s, t

    def sample_arrays(self, s, t) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Vectorised `point` and `curvature` at stations `s` (within the road) and offsets
        `t`: (x, y, heading, reference-line curvature), interpolated like the scalar calls."""
        s = np.asarray(s, dtype=float)
        x = np.interp(s, self._s, self._x)
        y = np.interp(s, self._s, self._y)
        h = np.interp(s, self._s, self._h)
        k = np.interp(s, self._s, self._k)
        return x - np.sin(h) * t, y + np.cos(h) * t, h, k

    def lane_center_t_array(self, lane: int, s) -> np.ndarray:
        """Vectorised `lane_center_t` (NaN where the lane is absent)."""
        self.lane_center_t(lane, 0.0)  # fills the lane's table
        return np.interp(np.asarray(s, dtype=float), self._s, self._center_cache[lane])

    def nearest_d2(self, x: float, y: float, s_lo: float, s_hi: float) -> float:
        """Squared distance [m^2] from a point to the nearest sample with s in [s_lo, s_hi]."""
        i0 = max(0, int(s_lo / self._ds))
        i1 = min(len(self._s) - 1, int(math.ceil(s_hi / self._ds)))
        d = self._xy[i0:i1 + 1] - (x, y)
        return float(np.min(np.einsum("ij,ij->i", d, d)))

    def road_band_t(self, s: float) -> tuple[float, float]:
        """(t_min, t_max) [m] of the road's outermost lane borders at `s` (clamped to the road)."""
        return self.road.road_band_t(min(max(s, 0.0), self.length))

    def paved_band_t(self, s: float) -> tuple[float, float]:
        """`Road.paved_band_t` at `s` (clamped to the road)."""
        return self.road.paved_band_t(min(max(s, 0.0), self.length))

    def project_along(self, x: float, y: float, hint: float) -> tuple[float, float, float]:
        """`project` from a hint, plus the point's distance along the tangent beyond the
        clamped station [m] (non-zero only past the road's ends): for routes."""
        s, t = self.project(x, y, hint)
        rx, ry, h = self.reference_pose(s)
        return s, t, (x - rx) * math.cos(h) + (y - ry) * math.sin(h)

    # ---- lanes
    def road_coords(self, s: float, t: float):
        """(OpenDRIVE road, its station [m], its t [m], the direction driven along it: +1) of
        a point at (`s`, `t`): the road itself (a `RoutePath` answers with its leg's road)."""
        return self.road, min(max(s, 0.0), self.length), t, 1

    def _section_key(self, s: float) -> int:
        return max(0, bisect.bisect_right(self._section_starts, s) - 1)

    def speed_limit(self, s: float) -> float | None:
        """The map's speed limit [m/s] at station `s` [m] (None where it gives none)."""
        return self.road.speed_limit(s)

    def driving_lane_ids(self, s: float) -> tuple[int, ...]:
        key = self._section_key(s)
        lanes = self._lanes_cache.get(key)  # hot (each actor's lane offset, every step): no call layer
        return lanes if lanes is not None else self._lanes_of_section(key)

    def _lanes_of_section(self, key: int) -> tuple[int, ...]:
        if key not in self._lanes_cache:
            sec = self.road.sections[key]
            self._lanes_cache[key] = tuple(self.road.driving_lane_ids(min(max(sec.s0 + 1e-6, 0.0), self.length)))
        return self._lanes_cache[key]

    def lane_center_t(self, lane: int, s: float) -> float:
        table = self._center_cache.get(lane)
        if table is None:
            try:
                vals = np.asarray(self.road.lane_center_t(lane, np.asarray(self._s)), dtype=float)
            except ValueError:
                vals = np.array([float(self.road.lane_center_t(lane, si)) if lane in self.road.lane_ids(si)
                                 else math.nan for si in self._s])
            table = vals.tolist()
            self._center_cache[lane] = table
        i, u = self._index(s)
        return table[i] + u * (table[i + 1] - table[i])

    def lane_at(self, s: float, t: float) -> int | None:
        best, best_d = None, math.inf
        for lane in self.driving_lane_ids(s):
            d = abs(t - self.lane_center_t(lane, s))
            if d < best_d:
                best, best_d = lane, d
        return best

    def lane_offset(self, s: float, t: float) -> float:
        """Offset from the nearest driving lane's centre [m]: `lane_at`'s lane, each
        centre interpolated once (the loop asks for every actor at every step)."""
        i, u = self._index(s)
        best_d, best_c = math.inf, None
        for lane in self.driving_lane_ids(s):
            table = self._center_cache.get(lane)
            if table is None:
                self.lane_center_t(lane, s)  # fills the lane's table
                table = self._center_cache[lane]
            c = table[i] + u * (table[i + 1] - table[i])
            d = abs(t - c)
            if d < best_d:
                best_d, best_c = d, c
        return t if best_c is None else t - best_c
