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
    ch, sh = np.cos(heading), np.sin(heading)
    # Nose-up pitch is a negative rotation about the body's left-pointing y axis.
    cp, sp = np.cos(pitch), np.sin(-pitch)
    rot = np.empty((len(heading), 3, 3))
    rot[:, 0, 0], rot[:, 0, 1], rot[:, 0, 2] = ch * cp, -sh, ch * sp
    rot[:, 1, 0], rot[:, 1, 1], rot[:, 1, 2] = sh * cp, ch, sh * sp
    rot[:, 2, 0], rot[:, 2, 1], rot[:, 2, 2] = -sp, 0.0, cp
    return rot


def cast(starts: np.ndarray, ends: np.ndarray, centres: np.ndarray, rotations: np.ndarray,
         half_extents: np.ndarray, plane_z: float | None = None,
         plane_hits: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """First hit of each segment starts[i] → ends[i] (N×3) among M boxes and a plane.

    Boxes: `centres` (M×3), `rotations` (M×3×3, columns are the box axes in the world),
    `half_extents` (M×3). `plane_z`: height of the horizontal ground plane, or None.
    Returns (index, fraction): index k < M for box k, M for the plane, -1 for no hit
    (fraction 1.0 there). With `plane_hits=False` the plane only hides boxes behind it: a
    ray whose first hit is the plane reports -1 as well (for a caller that drops ground
    hits). Ties between boxes go to the lower index.
    """
    n = len(starts)
    index = np.empty(n, dtype=np.int64)
    frac = np.empty(n)
    f = np.float64
    _cast(np.ascontiguousarray(starts, dtype=f), np.ascontiguousarray(ends, dtype=f),
          np.ascontiguousarray(centres, dtype=f).reshape(-1, 3),
          np.ascontiguousarray(rotations, dtype=f).reshape(-1, 3, 3),
          np.ascontiguousarray(half_extents, dtype=f).reshape(-1, 3), 0.0 if plane_z is None else float(plane_z),
          plane_z is not None, plane_hits, index, frac)
    return index, frac


@kernel
def _cast(starts, ends, centres, rotations, half, plane_z, has_plane, plane_hits, index, frac):
    """`cast` into `index` and `frac`. Per ray, the boxes whose bounding sphere the segment
    may meet (with slack: a false candidate costs one slab test) get the exact slab test."""
    n, m = starts.shape[0], centres.shape[0]
    radius = np.empty(m)
    for k in range(m):
        radius[k] = math.sqrt(half[k, 0] * half[k, 0] + half[k, 1] * half[k, 1] + half[k, 2] * half[k, 2])
    for i in range(n):
        sx, sy, sz = starts[i, 0], starts[i, 1], starts[i, 2]
        gx, gy, gz = ends[i, 0] - sx, ends[i, 1] - sy, ends[i, 2] - sz
        length = math.sqrt(gx * gx + gy * gy + gz * gz)
        best, hit = math.inf, -1
        for k in range(m):
            rx, ry, rz = centres[k, 0] - sx, centres[k, 1] - sy, centres[k, 2] - sz
            # distance from the centre to the segment's line, within the segment's reach
            reach = length + radius[k]
            d2 = rx * rx + ry * ry + rz * rz
            if d2 > reach * reach * (1.0 + 1e-9) + 1e-9:
                continue
            if length > 0.0:  # the closest point of the segment to the centre
                proj = (rx * gx + ry * gy + rz * gz) / length
                along = min(max(proj, 0.0), length)
                dist2 = d2 - along * (2.0 * proj - along)
                if dist2 > radius[k] * radius[k] * (1.0 + 1e-9) + 1e-9 * (1.0 + d2):
                    continue
            t = _slab(sx - centres[k, 0], sy - centres[k, 1], sz - centres[k, 2], gx, gy, gz, rotations[k], half[k])
            if t < best:
                best, hit = t, k
        if has_plane:
            above_start, above_end = sz - plane_z, ends[i, 2] - plane_z
            t = above_start / (above_start - above_end)
            # Strictly crossing, as Bullet's triangle ray test: an endpoint on the plane is no hit.
            if above_start * above_end < 0.0 and t < best and (plane_hits or hit >= 0):
                if plane_hits:
                    best, hit = t, m
                else:
                    hit = -1
        index[i] = hit
        frac[i] = best if hit >= 0 else 1.0


@kernel
def _slab(ox, oy, oz, gx, gy, gz, rot, half):
    """Entry fraction of a segment (start relative to the box centre, direction g) into
    the box (axes the columns of `rot`, half extents `half`); inf for a miss or a segment
    that starts inside (pybullet reports neither)."""
    t_near, t_far = -math.inf, math.inf
    for a in range(3):
        # into the box frame: R^T v, summed in numpy's einsum order
        o = rot[0, a] * ox + rot[1, a] * oy + rot[2, a] * oz
        d = rot[0, a] * gx + rot[1, a] * gy + rot[2, a] * gz
        inv = 1.0 / d  # ±inf on an axis-parallel segment: the slab is all or nothing
        t1 = (-half[a] - o) * inv
        t2 = (half[a] - o) * inv
        t_near = maximum(t_near, minimum(t1, t2))
        t_far = minimum(t_far, maximum(t1, t2))
    if t_near <= t_far and t_near >= 0.0 and t_near <= 1.0:
        return t_near
    return math.inf
