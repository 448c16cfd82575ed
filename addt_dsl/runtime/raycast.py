"""Exact ray casts against oriented boxes and a horizontal plane (a compiled kernel).

The twin's collision world is, on flat roads, just that: actor boxes posed by the loop
and the infinite ground plane. For such a world `cast` answers what pybullet's
`rayTestBatch` answers (the first body each ray segment meets, and where), without the
per-ray overhead of the engine: a slab test per box in the box's frame, in float64, one
compiled call per cast (`addt_dsl/kernel.py`). `PhysicsWorld.ray_cast` uses it whenever
the world is eligible (no collision meshes) and falls back to pybullet otherwise.

Matched pybullet semantics (checked against `rayTestBatch` in tests/unit/runtime/test_raycast.py):
- a ray that starts inside a box does not hit that box (it may hit others);
- the ground plane is hit from either side, by segments that strictly cross it;
- hits are reported as the fraction of the segment start → end, endpoints included.
Rays that graze an edge or a face exactly (measure zero) may differ.
"""

from __future__ import annotations

import math

import numpy as np

from addt_dsl.kernel import kernel, maximum, minimum


def box_rotations(heading: np.ndarray, pitch: np.ndarray) -> np.ndarray:
    """(M, 3, 3) rotations Rz(heading) @ Ry(-pitch): the body poses `PhysicsWorld.set_pose` makes."""
    # Nose-up pitch is a negative rotation about the body's left-pointing y axis.
    rot = np.empty((len(heading), 3, 3))
    _rotations(np.cos(heading), np.sin(heading), np.cos(pitch), np.sin(-pitch), rot)
    return rot


@kernel
def _rotations(ch, sh, cp, sp, rot):
    """`box_rotations` into `rot` from the angles' cosines and sines (numpy's)."""
    for k in range(rot.shape[0]):
        rot[k, 0, 0], rot[k, 0, 1], rot[k, 0, 2] = ch[k] * cp[k], -sh[k], ch[k] * sp[k]
        rot[k, 1, 0], rot[k, 1, 1], rot[k, 1, 2] = sh[k] * cp[k], ch[k], sh[k] * sp[k]
        rot[k, 2, 0], rot[k, 2, 1], rot[k, 2, 2] = -sp[k], 0.0, cp[k]


def cast(starts: np.ndarray, ends: np.ndarray, centres: np.ndarray, rotations: np.ndarray,
         half_extents: np.ndarray, plane_z: float | None = None,
         plane_hits: bool = True, ignore: int = -1) -> tuple[np.ndarray, np.ndarray]:
    """First hit of each segment starts[i] → ends[i] (N×3) among M boxes and a plane.

    `starts` may be one row for every ray (1×3, or N×3 broadcast from one row: a scan).
    Boxes: `centres` (M×3), `rotations` (M×3×3, columns are the box axes in the world),
    `half_extents` (M×3). `plane_z`: height of the horizontal ground plane, or None.
    Returns (index, fraction): index k < M for box k, M for the plane, -1 for no hit
    (fraction 1.0 there). With `plane_hits=False` the plane only hides boxes behind it: a
    ray whose first hit is the plane reports -1 as well (for a caller that drops ground
    hits); likewise a ray whose first hit is box `ignore` (a caller's own body). Ties
    between boxes go to the lower index.
    """
    n = len(ends)
    index = np.empty(n, dtype=np.int64)
    frac = np.empty(n)
    f = np.float64
    starts = np.asarray(starts, dtype=f)
    if starts.ndim == 2 and len(starts) > 1 and starts.strides[0] == 0:
        starts = starts[:1]  # one origin, as broadcast
    _cast(np.ascontiguousarray(starts, dtype=f).reshape(-1, 3), np.ascontiguousarray(ends, dtype=f).reshape(-1, 3),
          np.ascontiguousarray(centres, dtype=f).reshape(-1, 3),
          np.ascontiguousarray(rotations, dtype=f).reshape(-1, 3, 3),
          np.ascontiguousarray(half_extents, dtype=f).reshape(-1, 3), 0.0 if plane_z is None else float(plane_z),
          plane_z is not None, plane_hits, ignore, index, frac)
    return index, frac


LONG = 2.0 ** 100  # [m] segments up to this long, boxes up to this size: see `_frame`


@kernel
def _cast(starts, ends, centres, rotations, half, plane_z, has_plane, plane_hits, ignore, index, frac):
    """`cast` into `index` and `frac`. Per ray, the boxes whose bounding sphere the segment
    may meet (with slack: a false candidate costs one slab test) get the exact slab test,
    but a box the ray starts well inside (`_frame`), which it cannot hit. What depends on
    the start alone is computed once per start: a scan's rays share it."""
    n, m = ends.shape[0], centres.shape[0]
    shared = starts.shape[0] == 1
    radius = np.empty(m)
    for k in range(m):
        radius[k] = math.sqrt(half[k, 0] * half[k, 0] + half[k, 1] * half[k, 1] + half[k, 2] * half[k, 2])
    # Of each box from the current start: the centre less the start (3) and its length²;
    # the start in the box's frame (3) and whether it lies well inside, once asked (`framed`);
    # whether the start is outside the sphere test (then so is a segment leading away).
    near = np.empty((m, 9))
    framed = np.zeros(m, dtype=np.bool_)
    px = py = pz = 0.0
    for i in range(n):
        j = 0 if shared else i
        sx, sy, sz = starts[j, 0], starts[j, 1], starts[j, 2]
        if i == 0 or not (shared or (_same(sx, px) and _same(sy, py) and _same(sz, pz))):
            px, py, pz = sx, sy, sz
            for k in range(m):
                rx, ry, rz = centres[k, 0] - sx, centres[k, 1] - sy, centres[k, 2] - sz
                near[k, 0], near[k, 1], near[k, 2] = rx, ry, rz
                d2 = rx * rx + ry * ry + rz * rz
                near[k, 3] = d2
                near[k, 8] = 1.0 if d2 > radius[k] * radius[k] * (1.0 + 1e-9) + 1e-9 * (1.0 + d2) else 0.0
                framed[k] = False
        gx, gy, gz = ends[i, 0] - sx, ends[i, 1] - sy, ends[i, 2] - sz
        length = math.sqrt(gx * gx + gy * gy + gz * gz)
        short = length <= LONG
        best, hit = math.inf, -1
        for k in range(m):
            if framed[k] and near[k, 7] != 0.0 and short:
                continue
            rx, ry, rz, d2 = near[k, 0], near[k, 1], near[k, 2], near[k, 3]
            # distance from the centre to the segment's line, within the segment's reach
            reach = length + radius[k]
            if d2 > reach * reach * (1.0 + 1e-9) + 1e-9:
                continue
            if length > 0.0:  # the closest point of the segment to the centre
                dot = rx * gx + ry * gy + rz * gz
                if -math.inf < dot <= 0.0:  # it is the start (dist2 is d2): the test is the start's
                    if near[k, 8] != 0.0:
                        continue
                else:
                    proj = dot / length
                    along = min(max(proj, 0.0), length)
                    dist2 = d2 - along * (2.0 * proj - along)
                    if dist2 > radius[k] * radius[k] * (1.0 + 1e-9) + 1e-9 * (1.0 + d2):
                        continue
            if not framed[k]:
                _frame(sx - centres[k, 0], sy - centres[k, 1], sz - centres[k, 2], rotations[k], half[k], near[k])
                framed[k] = True
                if near[k, 7] != 0.0 and short:
                    continue
            t = _slab(near[k, 4:7], gx, gy, gz, rotations[k], half[k])
            if t < best:
                best, hit = t, k
        if has_plane:
            above_start, above_end = sz - plane_z, ends[i, 2] - plane_z
            # Strictly crossing, as Bullet's triangle ray test: an endpoint on the plane is no hit.
            if above_start * above_end < 0.0 and (plane_hits or hit >= 0):
                t = above_start / (above_start - above_end)
                if t < best:
                    if plane_hits:
                        best, hit = t, m
                    else:
                        hit = -1
        if hit == ignore:
            hit = -1
        index[i] = hit
        frac[i] = best if hit >= 0 else 1.0


cast_into = _cast
"""`cast` for a kernel, which calls it by this name: (starts (1 or N rows), ends, centres,
rotations, half extents, plane z [m], whether there is a plane, whether its hits count,
the box to ignore or -1, then `index` and `frac` to fill)."""


@kernel
def _same(a, b):
    """Whether two floats have the same bits (but NaNs, never the same: recomputed)."""
    return a == b and math.copysign(1.0, a) == math.copysign(1.0, b)


@kernel
def _frame(ox, oy, oz, rot, half, out):
    """A start (relative to the box centre) in the box's frame, out[4:7] (R^T v, summed in
    numpy's einsum order, as `_slab` takes it), and out[7]: 1.0 where the start lies well
    inside the box, so that `_slab` returns inf for any segment up to `LONG` long, else 0.0.

    Well inside: on every axis |o| <= half - 2^-100, half <= 2^100 and the axis' direction
    sums |rot[:, a]| <= 2^10 (finite). Then the segment's component d along the axis has
    |d| < 2^112, so 1 / d is ±inf or at least 2^-113 in size, and the axis' entry
    min((-half - o) / d, (half - o) / d) is strictly negative (-inf, or a normal number
    of size over 2^-214, never an underflow to -0): so is the largest entry, t_near."""
    well_inside = True
    for a in range(3):
        o = rot[0, a] * ox + rot[1, a] * oy + rot[2, a] * oz
        out[4 + a] = o
        if not (half[a] - abs(o) >= 2.0 ** -100 and half[a] <= 2.0 ** 100
                and abs(rot[0, a]) + abs(rot[1, a]) + abs(rot[2, a]) <= 2.0 ** 10):
            well_inside = False
    out[7] = 1.0 if well_inside else 0.0


@kernel
def _slab(start, gx, gy, gz, rot, half):
    """Entry fraction of a segment (`start` in the box frame, `_frame`; direction g in the
    world) into the box (axes the columns of `rot`, half extents `half`); inf for a miss or
    a segment that starts inside (pybullet reports neither)."""
    t_near, t_far = -math.inf, math.inf
    for a in range(3):
        o = start[a]
        # into the box frame: R^T g, summed in numpy's einsum order
        d = rot[0, a] * gx + rot[1, a] * gy + rot[2, a] * gz
        inv = 1.0 / d  # ±inf on an axis-parallel segment: the slab is all or nothing
        t1 = (-half[a] - o) * inv
        t2 = (half[a] - o) * inv
        t_near = maximum(t_near, minimum(t1, t2))
        t_far = minimum(t_far, maximum(t1, t2))
        # t_near only grows, t_far only shrinks (or turn NaN): a miss now is a miss
        if t_near > t_far or t_far < 0.0 or t_near > 1.0:
            return math.inf
    if t_near <= t_far and t_near >= 0.0 and t_near <= 1.0:
        return t_near
    return math.inf
