"""A sampled view of one road for the simulation loop's hot path.

`Road` (addt_dsl.road) evaluates OpenDRIVE geometry exactly but costs ~10-500 µs per
scalar call; the loop asks for poses and projections thousands of times per run. This
view samples the reference line once per run (every `STEP_M`) and answers by
interpolation (a few µs; under 1 µs a call compiled). The interpolation error on a sample
spacing of 0.25 m is below kappa * ds^2 / 8, i.e. under 1e-4 m for curvatures up to 0.01 /m.

Each query is one compiled kernel (`addt_dsl.kernel`) over the road's sample table: the
scalar calls (`reference_pose`, `point`, `ground_scale`, `lane_offset`, `project`) call it
on one point, `pose_rows` runs the same functions over many actors in one call (the agents'
pose phase, `agents.Fleets`), so the two give the same bits.
"""

from __future__ import annotations

import bisect
import math

import numpy as np

from addt_dsl.kernel import bisect_right, kernel
from addt_dsl.runtime.agent_arrays import SCALE, S, T
from addt_dsl.runtime.roadmesh import elevation_at

STEP_M = 0.25
MIN_GROUND_SCALE = 0.2  # [m/m] `ground_scale` near a bend's centre of curvature
_BLOCK = 8192  # samples evaluated at once
_NO_PROFILE = np.empty(0)  # `_pose_rows`' elevation samples on a flat road

# Rows of a road's sample table (`FastRoad._tab`): the reference line's x, y [m], unwrapped
# heading [rad], curvature [1/m] and station [m] at each sample.
_X, _Y, _H, _K, _S = range(5)
# Rows of `pose_rows`' output: x, y, z [m], the road's heading [rad], the lane offset [m], the grade [-].
POSE_X, POSE_Y, POSE_Z, POSE_H, POSE_OFFSET, POSE_GRADE = range(6)


@kernel
def _index(tab, ds, last_i, s):
    """(sample index, fraction) of station `s`: int(s / ds) clamped to the samples (clamping
    the quotient first gives the same index)."""
    q = s / ds
    if q != q:  # int() of it raised, and raises (as interpreted, its words too)
        raise ValueError("cannot convert float NaN to integer")
    if q - q != 0.0:
        raise OverflowError("cannot convert float infinity to integer")
    if q < 0.0:
        q = 0.0
    elif q > last_i:
        q = float(last_i)
    i = int(q)
    return i, (s - tab[_S, i]) / ds


@kernel
def reference_pose_at(tab, ds, last_i, length, s):
    i, u = _index(tab, ds, last_i, s)
    x = tab[_X, i] + u * (tab[_X, i + 1] - tab[_X, i])
    y = tab[_Y, i] + u * (tab[_Y, i + 1] - tab[_Y, i])
    h = tab[_H, i] + u * (tab[_H, i + 1] - tab[_H, i])
    if s > length:  # extrapolate straight past the end
        extra = s - length
        h = tab[_H, last_i + 1]
        x, y = tab[_X, last_i + 1] + extra * math.cos(h), tab[_Y, last_i + 1] + extra * math.sin(h)
    elif s < 0.0:
        h = tab[_H, 0]
        x, y = tab[_X, 0] + s * math.cos(h), tab[_Y, 0] + s * math.sin(h)
    return x, y, h


@kernel
def curvature_at(tab, ds, last_i, s):
    """The reference line's curvature [1/m] at station s [m] (`FastRoad.curvature`), for
    other kernels."""
    i, u = _index(tab, ds, last_i, s)
    return tab[_K, i] + u * (tab[_K, i + 1] - tab[_K, i])


@kernel
def _point(tab, ds, last_i, length, s, t):
    x, y, h = reference_pose_at(tab, ds, last_i, length, s)
    return x - math.sin(h) * t, y + math.cos(h) * t, h


@kernel
def _ground_scale(tab, ds, last_i, length, s, t):
    if s > length or s < 0.0:
        return 1.0
    i, u = _index(tab, ds, last_i, s)
    g = 1.0 - (tab[_K, i] + u * (tab[_K, i + 1] - tab[_K, i])) * t
    return g if g > MIN_GROUND_SCALE else MIN_GROUND_SCALE


@kernel
def _section(starts, s):
    """The lane section at `s`: bisect_right(starts, s) - 1, at least 0."""
    lo = bisect_right(starts, s, starts.size)
    return lo - 1 if lo > 0 else 0


@kernel
def _lane_offset(centres, starts, lanes, i, u, s, t):
    """(offset from the nearest driving lane's centre at sample `i` + fraction `u`, the first
    of equal distances; -1, or the section whose lanes' centres are not in `centres` yet).
    `lanes[k]`: section k's lane count (-1: not tabled yet), then its rows of `centres`."""
    k = _section(starts, s)
    n = lanes[k, 0]
    if n < 0:
        return t, k
    best_d, best_c = math.inf, 0.0
    found = False
    for j in range(1, n + 1):
        row = lanes[k, j]
        c = centres[row, i] + u * (centres[row, i + 1] - centres[row, i])
        d = abs(t - c)
        if d < best_d:  # (an absent lane's NaN is never nearer)
            best_d, best_c, found = d, c, True
    return (t - best_c if found else t), -1


@kernel
def _lane_offset_at(tab, ds, last_i, centres, starts, lanes, s, t):
    i, u = _index(tab, ds, last_i, s)
    return _lane_offset(centres, starts, lanes, i, u, s, t)


@kernel
def _project(tab, ds, last_i, length, x, y, hint, hinted):
    """(s, t) of the point (`x`, `y`): three Newton steps along the line from `hint`, or
    without one from the nearest sample (the first of the nearest; the first NaN distance, as
    numpy's argmin)."""
    s = hint
    if not hinted:
        best, best_d = 0, (tab[_X, 0] - x) * (tab[_X, 0] - x) + (tab[_Y, 0] - y) * (tab[_Y, 0] - y)
        if best_d == best_d:
            for k in range(1, tab.shape[1]):
                dx, dy = tab[_X, k] - x, tab[_Y, k] - y
                d = dx * dx + dy * dy
                if d != d:
                    best = k
                    break
                if d < best_d:
                    best, best_d = k, d
        s = tab[_S, best]
    for _ in range(3):
        rx, ry, h = reference_pose_at(tab, ds, last_i, length, s)
        step = (x - rx) * math.cos(h) + (y - ry) * math.sin(h)
        s += step
        if s < 0.0:
            s = 0.0
        elif s > length:
            s = length
        if abs(step) < 1e-6:
            break
    rx, ry, h = reference_pose_at(tab, ds, last_i, length, s)
    return s, -(x - rx) * math.sin(h) + (y - ry) * math.cos(h)


_BOX = 128  # samples per bounding box of `_nearest_boxed`


@kernel
def _box_d2(boxes, b, x, y):
    """A lower bound of the squared distance `_project` computes from (`x`, `y`) to any
    sample in box `b` (x min, x max, y min, y max): rounding is monotone, so the same
    operations on the box's nearer edge give at most any of its samples' distance."""
    ex = boxes[b, 0] - x if x < boxes[b, 0] else (x - boxes[b, 1] if x > boxes[b, 1] else 0.0)
    ey = boxes[b, 2] - y if y < boxes[b, 2] else (y - boxes[b, 3] if y > boxes[b, 3] else 0.0)
    return ex * ex + ey * ey


project_hinted = _project
"""`FastRoad.project` for a kernel, which calls it by this name: (s, t) [m] of (x, y) on sample
table `tab`, three Newton steps from `hint` where `hinted`."""


@kernel
def project_boxed(tab, ds, last_i, length, boxes, x, y):
    """`_project` without a hint, its bits: the nearest sample (the first of the nearest)
    found through the samples' bounding boxes (`FastRoad.boxes`), every `_BOX` samples a box:
    the least distance in the box of the least bound bounds the answer, and only boxes
    within it are searched. A point not finite, or no boxes, searches every sample."""
    nb = boxes.shape[0]
    if nb == 0 or not (x - x == 0.0 and y - y == 0.0):
        return _project(tab, ds, last_i, length, x, y, 0.0, False)
    n = tab.shape[1]
    near, near_lb = 0, math.inf
    for b in range(nb):
        lb = _box_d2(boxes, b, x, y)
        if lb < near_lb:
            near, near_lb = b, lb
    bound = math.inf
    for k in range(near * _BOX, min((near + 1) * _BOX, n)):
        d = (tab[_X, k] - x) * (tab[_X, k] - x) + (tab[_Y, k] - y) * (tab[_Y, k] - y)
        if d < bound:
            bound = d
    best, best_d = 0, math.inf
    for b in range(nb):
        if _box_d2(boxes, b, x, y) > bound:
            continue
        for k in range(b * _BOX, min((b + 1) * _BOX, n)):
            d = (tab[_X, k] - x) * (tab[_X, k] - x) + (tab[_Y, k] - y) * (tab[_Y, k] - y)
            if d < best_d:
                best, best_d = k, d
    return _project(tab, ds, last_i, length, x, y, tab[_S, best], True)


@kernel
def _pose_rows(tab, ds, last_i, length, centres, starts, lanes, z, g, z_ds, z_length, flat, cells, rows, out):
    """Every actor of one road: row r = rows[j] is block slot cells[r] (`AgentArrays.flat`):
    its point, lane offset, elevation (`z` empty: a flat road) into out[:, r] (`POSE_*`),
    its ground scale into the block. -1; or a section `lanes` lacks, or -2 at a station or
    offset not finite (nothing is written from that actor on)."""
    for j in range(rows.size):
        r = rows[j]
        cell = cells[r]
        s, t = flat[S, cell], flat[T, cell]
        if not (s - s == 0.0 and t - t == 0.0):
            return -2
        i, u = _index(tab, ds, last_i, s)
        off, missing = _lane_offset(centres, starts, lanes, i, u, s, t)
        if missing >= 0:
            return missing
        out[POSE_X, r], out[POSE_Y, r], out[POSE_H, r] = _point(tab, ds, last_i, length, s, t)
        out[POSE_OFFSET, r] = off
        flat[SCALE, cell] = _ground_scale(tab, ds, last_i, length, s, t)
        if z.size:
            out[POSE_Z, r], out[POSE_GRADE, r] = elevation_at(z, g, z_ds, z_length, s)
        else:
            out[POSE_Z, r], out[POSE_GRADE, r] = 0.0, 0.0
    return -1



@kernel
def _ego_poses(tab, ds, last_i, length, centres, starts, lanes, z, g, z_ds, z_length, points, rows, hints, out):
    """Row j: point rows[j] of `points` (x, y, heading its first columns) into out[j] as (x,
    y, heading, s, t, lane offset, z, grade): `_project` from hints[j], `_lane_offset_at`,
    `elevation_at` (`z` empty: a flat road, 0). -1; or a section `lanes` lacks, or -2 at a
    point or hint not finite (nothing is trusted then)."""
    for j in range(rows.size):
        r = rows[j]
        x, y, hint = points[r, 0], points[r, 1], hints[j]
        if not (x - x == 0.0 and y - y == 0.0 and hint - hint == 0.0):
            return -2
        s, t = _project(tab, ds, last_i, length, x, y, hint, True)
        off, missing = _lane_offset_at(tab, ds, last_i, centres, starts, lanes, s, t)
        if missing >= 0:
            return missing
        out[j, 0], out[j, 1], out[j, 2] = x, y, points[r, 2]
        out[j, 3], out[j, 4], out[j, 5] = s, t, off
        if z.size:
            out[j, 6], out[j, 7] = elevation_at(z, g, z_ds, z_length, s)
        else:
            out[j, 6], out[j, 7] = 0.0, 0.0
    return -1


class FastRoad:
    _boxes: np.ndarray | None = None  # `project_boxed`'s bounding boxes, made when first asked
    _k_a: np.ndarray | None = None  # the curvature samples (and `_s_k` their stations) as arrays, made when first asked
    _lane_tables: tuple | None = None  # (centres, section starts, lanes) of `_lane_offset`, made when first asked

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
        self._table()
        self._section_starts = [sec.s0 for sec in road.sections]
        self._lanes_cache: dict[int, tuple[int, ...]] = {}
        self._center_cache: dict[int, list[float]] = {}
        self._center_rows: dict[int, np.ndarray] = {}  # the same centres as arrays (`_lanes_tabled`)

    def _table(self) -> None:
        """The kernels' table of the samples (`_X`..`_S` rows) and its spacing."""
        self._tab = np.array([self._x, self._y, self._h, self._k, self._s])
        self._ds = self._s[1] - self._s[0]
        self._last_i = len(self._s) - 2
        self._boxes = None

    def boxes(self) -> np.ndarray:
        """(x min, x max, y min, y max) [m] of every `_BOX` samples in a row (`project_boxed`);
        none where a sample is not finite (a NaN would end `_project`'s search)."""
        if self._boxes is None:
            xy = self._tab[[_X, _Y]]
            if not np.isfinite(xy).all():
                self._boxes = np.empty((0, 4))
            else:
                n = xy.shape[1]
                pad = -n % _BOX  # the last box repeats its last sample
                x = np.concatenate([xy[0], np.full(pad, xy[0, -1])]).reshape(-1, _BOX)
                y = np.concatenate([xy[1], np.full(pad, xy[1, -1])]).reshape(-1, _BOX)
                self._boxes = np.stack([x.min(1), x.max(1), y.min(1), y.max(1)], axis=1)
        return self._boxes

    # ---- reference line
    @property
    def table(self) -> tuple[np.ndarray, float, int, float]:
        """(sample table, sample spacing [m], last interval, length [m]): the reference line
        as this module's kernels read it (`reference_pose_at`, `curvature_at`,
        `project_hinted`), for kernels elsewhere that call them."""
        return self._tab, self._ds, self._last_i, self.length

    def _index(self, s: float) -> tuple[int, float]:
        return _index(self._tab, self._ds, self._last_i, s)

    def reference_pose(self, s: float) -> tuple[float, float, float]:
        return reference_pose_at(self._tab, self._ds, self._last_i, self.length, s)

    def pose_rows(self, elevation, flat: np.ndarray, cells: np.ndarray, rows: np.ndarray, out: np.ndarray) -> bool:
        """`point`, `lane_offset` and `elevation.at` of the actors in block slots
        cells[rows] (`AgentArrays.flat`) into out[POSE_*, rows], and `ground_scale` into the
        block's ground scales: one kernel call, the scalar calls' code and bits. False (and
        some left unposed) where a station or offset is not finite."""
        return self._on_lanes(_pose_rows, elevation, flat, cells, rows, out)

    def ego_poses(self, elevation, points: np.ndarray, rows: np.ndarray, hints: np.ndarray,
                  out: np.ndarray) -> bool:
        """Vehicles on this road, each from a nearby station: for each j, block row rows[j] of
        `points` (x, y, heading its first three columns) into out[j] as (x, y, heading, s, t,
        lane offset, z, grade): `project` from hints[j], `lane_offset` and `elevation.at`,
        one kernel call with the scalar calls' code and bits. False where a coordinate or
        hint is not finite (then none is to be used)."""
        return self._on_lanes(_ego_poses, elevation, points, rows, hints, out)

    def _on_lanes(self, pose_kernel, elevation, *args) -> bool:
        """`pose_kernel` (`_pose_rows`, `_ego_poses`) over this road's line, lane tables and
        `elevation`, then `args`; called again with the sections it asks for tabled (its -1:
        done, True; -2: a value not finite, False; else the section it lacks)."""
        centres, starts, lanes = self._lane_tables or self._lanes_tabled(-1)
        z, g = (elevation._z_a, elevation._g_a) if not elevation.flat else (_NO_PROFILE, _NO_PROFILE)
        while True:
            missing = pose_kernel(self._tab, self._ds, self._last_i, self.length, centres, starts, lanes, z, g,
                                  elevation._ds, elevation.length, *args)
            if missing == -1:
                return True
            if missing == -2:
                return False
            centres, starts, lanes = self._lanes_tabled(missing)

    def curvature(self, s: float) -> float:
        i, u = _index(self._tab, self._ds, self._last_i, s)  # (as `curvature_at`: Python floats)
        return self._k[i] + u * (self._k[i + 1] - self._k[i])

    def ground_scale(self, s: float, t: float) -> float:
        """Ground covered per metre of station [m/m] by an actor at offset `t` [m]: the
        offset curve's length element, 1 - kappa * t for the reference line's curvature
        kappa (more on the outside of a bend, less on the inside), at least
        `MIN_GROUND_SCALE` (near the centre of curvature). An actor moving at `speed`
        advances its station by speed / ground_scale. Past the ends, where the line goes on
        straight, 1."""
        return _ground_scale(self._tab, self._ds, self._last_i, self.length, s, t)

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
        return _point(self._tab, self._ds, self._last_i, self.length, s, t)

    def project(self, x: float, y: float, hint: float | None = None) -> tuple[float, float]:
        """(s, t) of a point; `hint` (a nearby s) makes it a local search (under 1 µs), without
        one it starts from the nearest sample (~1 ns a sample)."""
        return _project(self._tab, self._ds, self._last_i, self.length, x, y,
                        0.0 if hint is None else hint, hint is not None)

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
        return float(np.min(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]))

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
                vals = np.array(self.road.lane_center_t(lane, self._tab[_S]), dtype=float)
            except ValueError:
                vals = np.array([float(self.road.lane_center_t(lane, si)) if lane in self.road.lane_ids(si)
                                 else math.nan for si in self._s])
            table = vals.tolist()
            self._center_cache[lane] = table
            self._center_rows[lane] = vals
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
        centres, starts, lanes = self._lane_tables or self._lanes_tabled(-1)
        while True:
            off, missing = _lane_offset_at(self._tab, self._ds, self._last_i, centres, starts, lanes, s, t)
            if missing < 0:
                return off
            centres, starts, lanes = self._lanes_tabled(missing)

    def _lanes_tabled(self, key: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """`_lane_offset`'s tables with section `key`'s lanes in them (-1: none added): the
        centres of the driving lanes of the sections asked for so far (a lane's centre is
        sampled the first time a section with it is asked for, as `lane_center_t` does)."""
        if key >= 0:
            for lane in self._lanes_of_section(key):
                self.lane_center_t(lane, 0.0)  # fills the lane's table
        order = list(self._center_cache)
        centres = np.array([self._center_rows[lane] for lane in order]).reshape(len(order), len(self._s))
        starts = np.array(self._section_starts, dtype=float)
        counts = [len(self._lanes_cache[k]) for k in range(len(starts)) if k in self._lanes_cache]
        lanes = np.full((len(starts), 1 + max(counts, default=0)), -1, dtype=np.int64)
        for k, ids in self._lanes_cache.items():
            if all(lane in self._center_cache for lane in ids):
                lanes[k, 0] = len(ids)
                lanes[k, 1:1 + len(ids)] = [order.index(lane) for lane in ids]
        self._lane_tables = (centres, starts, lanes)
        return self._lane_tables
