"""Lidar points → bird's-eye-view feature grid, and the learned detector's fixed layout.

numpy and kernels (no torch): the compiler may import this module to list the detector's tensor
fault sites, and the training data pipeline and the runtime node share `build_grid`, so
what the network sees in training is exactly what it sees in the loop.

Grid (vehicle frame, x forward, y left, origin at the vehicle centre):
  x in [-60.8, 60.8) m, y in [-25.6, 25.6) m, 0.8 m cells → 152 × 64 cells.
  Objects up to about 60 m ahead or behind, and four lanes either side, are in view;
  the lateral extent is narrower because the detector is trained on road scenes.
Features per cell (8 channels, zero where no point falls):
  0 occupancy      min(count, 4) / 4
  1 mean dx        mean offset of the points from the cell centre, in cells ([-0.5, 0.5))
  2 mean dy        (sub-cell position: the grid is coarse, the points are not)
  3 max z          highest point above the ground [m] / 2
  4 ray cos        mean direction from the sensor to the points (where the sensor is:
  5 ray sin        a CNN is translation-equivariant and would not know it otherwise)
  6 range          mean horizontal distance from the sensor to the points [m] / 60
  7 count          log2(1 + count) / 5, not saturated at 4
The last two say how far the points are and how many there are: with them a height
tells which beam it came from (so whether the next beam passed over the object) and a
count of returns tells a width (the rays are 1° apart). A cyclist seen end on and a
pedestrian, or a crossing cyclist's side and a car's rear, differ mainly in those
(docs/stack.md, Evaluation). Weights trained on the first six channels still run:
the detector reads the channels its first layer has (`learned.load_model`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from addt_dsl.kernel import atan2, c_hypot, exp, kernel, log2, matmul, maximum

# The shipped detectors' sensors and tensor sites: the compiler checks against them too.
from addt_dsl.specs.stacks import (CAMERA_BEV_SITES, CAMERA_BEV_TENSOR_SITES, DETECTOR_LIDAR,  # noqa: F401
                                   DETECTOR_RIG, ENCODER_SITES, LAYER_SITES, TENSOR_SITES, DetectorLidar,
                                   DetectorRig)

CHANNELS = 8
RANGE_SCALE_M = 60.0  # channel 6: range / this
COUNT_LOG2_SCALE = 5.0  # channel 7: log2(1 + count) / this
OUTPUT_STRIDE = 2  # detector head cells are OUTPUT_STRIDE × cell = 1.6 m
# The box axis, not the heading, is regressed, as (sin 2θ, cos 2θ): a lidar box looks the
# same from either end, and regressing the heading spent the network on an unlearnable
# front/back guess (which end is the front comes from the tracker's motion and the lane).
HEAD_CHANNELS = ("heat", "off_x", "off_y", "log_l", "log_w", "sin2", "cos2")
# Object classes of the detector's class output (logits after the six box channels of
# `head.box`), and of the training data's labels. Actor kinds outside these (obstacles)
# are not in the training data.
CLASSES = ("car", "truck", "pedestrian", "cyclist")
BOX_CHANNELS = 6



@dataclass(frozen=True)
class GridSpec:
    """Geometry of the BEV grid [m]."""

    x_min: float = -60.8
    y_min: float = -25.6
    cell_m: float = 0.8
    nx: int = 152
    ny: int = 64
    # Points at or below this height are ground returns (a multi-channel lidar's lower
    # beams reach the road): dropped, as lidar stacks do, so they do not read as objects.
    ground_m: float = 0.3

    @property
    def shape(self) -> tuple[int, int, int]:
        return (CHANNELS, self.nx, self.ny)

    @property
    def head_shape(self) -> tuple[int, int]:
        return (self.nx // OUTPUT_STRIDE, self.ny // OUTPUT_STRIDE)

    @property
    def head_cell_m(self) -> float:
        return self.cell_m * OUTPUT_STRIDE


GRID = GridSpec()




def build_grid(points_vehicle: np.ndarray, sensor_xy: tuple[float, float], spec: GridSpec = GRID,
               out: np.ndarray | None = None) -> np.ndarray:
    """Scatter vehicle-frame points (N×3, z up from the ground) into a (CHANNELS, nx, ny) float32 grid.

    `sensor_xy` is where the stack believes the sensor is (nominal extrinsics) [m];
    `out`, if given, is overwritten in place (saves an allocation per frame).
    """
    return build_grid_region(points_vehicle, sensor_xy, spec, out)[0]


def build_grid_region(points_vehicle: np.ndarray, sensor_xy: tuple[float, float], spec: GridSpec = GRID,
                      out: np.ndarray | None = None,
                      dirty: tuple[int, int, int, int] | None = None) -> tuple[np.ndarray, tuple[int, int, int, int]]:
    """`build_grid`, and the occupied cells' bounding box: rows [r0, r1) along x, columns
    [c0, c1) along y ((0, 0, 0, 0) for an empty grid), from the points, not a scan of the grid.

    `dirty`: the region of `out` outside which it is already zero (the last call's
    region, when `out` is reused): only that is cleared (a whole grid costs ~10 us)."""
    grid = np.zeros(spec.shape, dtype=np.float32) if out is None else out
    if out is not None:
        if dirty is None:
            grid.fill(0.0)
        else:
            grid[:, dirty[0]:dirty[1], dirty[2]:dirty[3]] = 0.0
    if len(points_vehicle) == 0:
        return grid, (0, 0, 0, 0)
    px = points_vehicle[:, 0]
    py = points_vehicle[:, 1]
    fx = (px - spec.x_min) / spec.cell_m
    fy = (py - spec.y_min) / spec.cell_m
    ix = np.floor(fx).astype(np.int64)
    iy = np.floor(fy).astype(np.int64)
    keep = (ix >= 0) & (ix < spec.nx) & (iy >= 0) & (iy < spec.ny) & (points_vehicle[:, 2] > spec.ground_m)
    if not keep.all():
        ix, iy, fx, fy = ix[keep], iy[keep], fx[keep], fy[keep]
        px, py, pz = px[keep], py[keep], points_vehicle[keep, 2]
    else:
        pz = points_vehicle[:, 2]
    if len(ix) == 0:
        return grid, (0, 0, 0, 0)
    # Per-cell reductions over the occupied cells only (a scan fills ~1 % of the grid).
    region = np.empty(4, dtype=np.int64)
    _fill_cells(ix, iy, fx, fy, px, py, pz, float(sensor_xy[0]), float(sensor_xy[1]), spec.ny,
                grid.reshape(CHANNELS, spec.nx * spec.ny), region)
    return grid, tuple(region.tolist())


@kernel
def _fill_cells(ix, iy, fx, fy, px, py, pz, sensor_x, sensor_y, ny, views, region):
    """The channels of the cells the points fall in (cell ix * ny + iy, a point's fractional
    cell fx, fy, its x, y, z [m]) into `views` (channels x cells), and the cells' bounding box
    (rows, columns) into `region`: per cell in order of the points, as numpy's `unique`,
    `bincount` (sums in the points' order), `lexsort` (the last of the highest) and the
    C library's hypot gave them."""
    n_pts = ix.size
    flat = np.empty(n_pts, dtype=np.int64)
    for i in range(n_pts):
        flat[i] = ix[i] * ny + iy[i]
    cells = np.unique(flat)
    m = cells.size
    n = np.zeros(m, dtype=np.int64)
    sums = np.zeros((6, m))
    top = np.empty(m)
    for i in range(n_pts):
        j = np.searchsorted(cells, flat[i])
        rx, ry = px[i] - sensor_x, py[i] - sensor_y
        rnorm = c_hypot(rx, ry)
        if not (rnorm >= 1e-6 or rnorm != rnorm):  # np.maximum(., 1e-6): a NaN stays
            rnorm = 1e-6
        sums[0, j] += fx[i] - ix[i] - 0.5
        sums[1, j] += fy[i] - iy[i] - 0.5
        sums[2, j] += rx / rnorm
        sums[3, j] += ry / rnorm
        sums[4, j] += rnorm
        if n[j] == 0 or pz[i] >= top[j]:  # (of equal heights the last, as the stable sort leaves it)
            top[j] = pz[i]
        n[j] += 1
    for j in range(m):
        c, k = cells[j], n[j]
        views[0, c] = min(k, 4) / 4.0
        views[1, c] = sums[0, j] / k
        views[2, c] = sums[1, j] / k
        views[3, c] = top[j] / 2.0
        views[4, c] = sums[2, j] / k
        views[5, c] = sums[3, j] / k
        views[6, c] = sums[4, j] / k / RANGE_SCALE_M
        views[7, c] = log2(1.0 + k) / COUNT_LOG2_SCALE
    lo, hi = iy[0], iy[0]
    for i in range(n_pts):
        lo, hi = min(lo, iy[i]), max(hi, iy[i])
    # `cells` is sorted: its first and last give the rows (flat = row * ny + column).
    region[0], region[1], region[2], region[3] = cells[0] // ny, cells[m - 1] // ny + 1, lo, hi + 1


def sensor_points_to_vehicle(points_sensor: np.ndarray, ext) -> np.ndarray:
    """Map sensor-frame points to the vehicle frame with extrinsics `ext` (roll, pitch, yaw, x, y, z)."""
    cr, sr = math.cos(ext.roll), math.sin(ext.roll)
    cp, sp = math.cos(ext.pitch), math.sin(ext.pitch)
    cy, sy = math.cos(ext.yaw), math.sin(ext.yaw)
    rot = np.array([
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ])
    return matmul(points_sensor, rot.T) + np.array([ext.x, ext.y, ext.z])


# ---------------------------------------------------------------- targets and decoding

def encode_targets(boxes: np.ndarray, spec: GridSpec = GRID, sigma_cells: float = 0.8,
                   classes: np.ndarray | None = None):
    """CenterNet targets for vehicle-frame boxes (N×5: x, y, heading, length, width).

    Returns (heat (hx, hy), regression (6, hx, hy), mask (hx, hy)): a Gaussian peak per
    object on the head grid; at each object's centre cell the regression targets
    (offset from the cell centre in head cells, log length, log width, sin 2θ, cos 2θ of the
    heading θ). With `classes` (N indices into `CLASSES`) the regression has a 7th row,
    the class index at each centre cell.
    """
    hx, hy = spec.head_shape
    heat = np.zeros((hx, hy), dtype=np.float32)
    reg = np.zeros((BOX_CHANNELS + (classes is not None), hx, hy), dtype=np.float32)
    mask = np.zeros((hx, hy), dtype=np.float32)
    c = spec.head_cell_m
    gi = np.arange(hx)[:, None]
    gj = np.arange(hy)[None, :]
    for k, (x, y, heading, length, width) in enumerate(boxes):
        fi = (x - spec.x_min) / c - 0.5
        fj = (y - spec.y_min) / c - 0.5
        i, j = int(round(fi)), int(round(fj))
        if not (0 <= i < hx and 0 <= j < hy):
            continue
        g = np.exp(-((gi - fi) ** 2 + (gj - fj) ** 2) / (2.0 * sigma_cells ** 2)).astype(np.float32)
        np.maximum(heat, g, out=heat)
        heat[i, j] = 1.0
        reg[:BOX_CHANNELS, i, j] = (fi - i, fj - j, math.log(length), math.log(width),
                                    math.sin(2.0 * heading), math.cos(2.0 * heading))
        if classes is not None:
            reg[BOX_CHANNELS, i, j] = classes[k]
        mask[i, j] = 1.0
    return heat, reg, mask


def decode(heat: np.ndarray, reg: np.ndarray, threshold: float, spec: GridSpec = GRID,
           max_objects: int = 64, max_overlap_m: float | None = 0.3) -> np.ndarray:
    """Peaks of a (hx, hy) score map (3×3 local maxima at or above `threshold`; scores
    may be probabilities or logits) → boxes.

    Returns an (N, 7) array: x, y, heading, length, width, score (vehicle frame), class
    (index into `CLASSES`, the largest of the class logits that follow the six box rows of
    `reg`; -1 when `reg` has none), sorted by score, highest first. With `max_overlap_m`, a
    box that overlaps a higher-scoring one by more than that (vehicles cannot overlap) is
    dropped: the network may propose a car and a truck for the same face, or a phantom behind a long vehicle.
    """
    i = np.empty(max(min(max_objects, heat.size), 0), dtype=np.int64)
    j = np.empty_like(i)
    with np.errstate(over="ignore"):  # numpy compares the map with the threshold in its dtype
        limit = heat.dtype.type(threshold)
    found = _peaks(heat, limit, i, j)
    if found == 0:
        return np.zeros((0, 7))
    i, j = i[:found], j[:found]
    with np.errstate(all="ignore"):  # a fault can feed inf/nan in: it must flow out, not warn
        return _boxes(heat, reg, i, j, heat[i, j], spec, max_overlap_m)


@kernel
def _peaks(heat, threshold, rows, cols):
    """The cells at or above `threshold` that are 3×3 local maxima (beyond the border:
    -inf), the highest first (ties in row-major order), at most len(rows) of them, into
    `rows`, `cols`; returns how many. A plateau yields one peak: a peak is strictly above
    the four neighbours that come first in row-major order and at least equal to the four
    after (a NaN neighbour compares False: no peak)."""
    hx, hy = heat.shape
    limit = rows.shape[0]
    n = 0
    score = np.empty(limit, dtype=heat.dtype)
    for i in range(hx):
        for j in range(hy):
            v = heat[i, j]
            if not v >= threshold:
                continue
            peak = True
            for di in range(-1, 2):
                for dj in range(-1, 2):
                    if di == 0 and dj == 0:
                        continue
                    a, b = i + di, j + dj
                    u = heat[a, b] if 0 <= a < hx and 0 <= b < hy else -np.inf
                    before = di < 0 or (di == 0 and dj < 0)
                    if not (v > u if before else v >= u):
                        peak = False
            if not peak or limit == 0:
                continue
            # Insert by score, highest first, after its equals (a stable sort of -score);
            # the lowest falls off the end once `limit` are held.
            at = n if n < limit else limit - 1
            if n == limit and not v > score[at]:
                continue
            while at > 0 and v > score[at - 1]:
                if at < limit:
                    rows[at], cols[at], score[at] = rows[at - 1], cols[at - 1], score[at - 1]
                at -= 1
            rows[at], cols[at], score[at] = i, j, v
            if n < limit:
                n += 1
    return n


def _boxes(heat, reg, i, j, conf, spec, max_overlap_m):
    c = spec.head_cell_m
    r = reg[:, i, j].astype(np.float64)
    x = spec.x_min + (i + 0.5 + r[0]) * c
    y = spec.y_min + (j + 0.5 + r[1]) * c
    heading = 0.5 * atan2.over(r[4], r[5])  # the box axis, in [-π/2, π/2]
    cls = r[BOX_CHANNELS:].argmax(axis=0).astype(np.float64) if len(r) > BOX_CHANNELS else np.full(len(i), -1.0)
    boxes = np.stack([x, y, heading, exp.over(r[2]), exp.over(r[3]), conf.astype(np.float64), cls], axis=1)
    if max_overlap_m is not None and len(boxes) > 1:
        boxes = boxes[_keep_non_overlapping(boxes, max_overlap_m)]
    return boxes


def box_penetration(boxes: np.ndarray) -> np.ndarray:
    """Pairwise separation of oriented boxes (rows x, y, heading, length, width, ...) [m].

    Separating-axis test over the four edge normals of each pair: positive is a gap,
    negative the depth of overlap along the shallowest axis."""
    boxes = np.ascontiguousarray(boxes[:, :5], dtype=np.float64)
    sep = np.empty((len(boxes), len(boxes)))
    _separations(boxes, np.cos(boxes[:, 2]), np.sin(boxes[:, 2]), sep)  # numpy's cos, sin (test)
    return sep


_CORNER_X = (1.0, 1.0, -1.0, -1.0)  # the corners' signs along the box axis and across it
_CORNER_Y = (1.0, -1.0, -1.0, 1.0)


@kernel
def _separations(boxes, c, s, sep):
    """`box_penetration` into `sep` (n, n), as the vectorised numpy form computed it (NaN
    in, NaN out): box j's corners projected on box k's two edge normals, the gap between
    boxes i and j along the better of box k's axes, the better of i's and j's."""
    n = boxes.shape[0]
    cx, cy = np.empty((n, 4)), np.empty((n, 4))
    for b in range(n):
        hl, hw = 0.5 * boxes[b, 3], 0.5 * boxes[b, 4]
        for m in range(4):
            cx[b, m] = boxes[b, 0] + c[b] * hl * _CORNER_X[m] - s[b] * hw * _CORNER_Y[m]
            cy[b, m] = boxes[b, 1] + s[b] * hl * _CORNER_X[m] + c[b] * hw * _CORNER_Y[m]
    lo, hi = np.empty((n, 2, n)), np.empty((n, 2, n))  # [k, axis, box]
    for k in range(n):
        for axis in range(2):
            ax, ay = (c[k], s[k]) if axis == 0 else (-s[k], c[k])
            for b in range(n):
                low, high = math.inf, -math.inf
                nan = False
                for m in range(4):
                    v = ax * cx[b, m] + ay * cy[b, m]
                    nan = nan or math.isnan(v)
                    low, high = min(low, v), max(high, v)
                lo[k, axis, b], hi[k, axis, b] = (math.nan, math.nan) if nan else (low, high)
    for i in range(n):
        for j in range(n):
            best = math.nan
            for k in (i, j):
                g = maximum(maximum(lo[k, 0, j] - hi[k, 0, i], lo[k, 0, i] - hi[k, 0, j]),
                             maximum(lo[k, 1, j] - hi[k, 1, i], lo[k, 1, i] - hi[k, 1, j]))
                best = g if k == i else maximum(best, g)
            sep[i, j] = best


@kernel
def _non_overlapping(boxes, c, s, max_overlap_m, keep):
    """`_keep_non_overlapping` into `keep`; returns how many are kept."""
    n = boxes.shape[0]
    finite, apart = True, True
    for i in range(n):
        for col in range(5):
            finite = finite and math.isfinite(boxes[i, col])
    for i in range(n):
        reach_i = 0.5 * math.hypot(boxes[i, 3], boxes[i, 4])  # the C library's, as np.hypot
        for j in range(n):
            if i != j:
                reach_j = 0.5 * math.hypot(boxes[j, 3], boxes[j, 4])
                if math.hypot(boxes[i, 0] - boxes[j, 0], boxes[i, 1] - boxes[j, 1]) - (reach_i + reach_j) < 0.0:
                    apart = False
    if finite and apart:
        for i in range(n):
            keep[i] = i
        return n
    sep = np.empty((n, n))
    _separations(boxes, c, s, sep)
    kept = 0
    for i in range(n):  # highest score first
        ok = True
        for t in range(kept):
            if not sep[i, keep[t]] >= -max_overlap_m:
                ok = False
                break
        if ok:
            keep[kept] = i
            kept += 1
    return kept


def _keep_non_overlapping(boxes: np.ndarray, max_overlap_m: float) -> np.ndarray:
    """Indices of the boxes (highest score first) that no kept box overlaps by more than
    `max_overlap_m`. Boxes whose circumcircles are apart cannot overlap: the usual frame
    (separate vehicles) needs no separating-axis test; NaN from a fault fails every
    comparison, so such frames take the full test."""
    five = np.ascontiguousarray(boxes[:, :5], dtype=np.float64)
    keep = np.empty(len(boxes), dtype=np.int64)
    kept = _non_overlapping(five, np.cos(five[:, 2]), np.sin(five[:, 2]), float(max_overlap_m), keep)
    return keep[:kept]


# ---------------------------------------------------------------- camera BEV (`perception camera_bev`)

