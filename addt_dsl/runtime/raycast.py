"""Exact ray casts against oriented boxes and a horizontal plane (pure numpy).

The twin's collision world is, on flat roads, just that: actor boxes posed by the loop
and the infinite ground plane. For such a world `cast` answers what pybullet's
`rayTestBatch` answers (the first body each ray segment meets, and where), without the
per-ray overhead of the engine: a vectorised slab test per box in the box's frame, in
float64. `PhysicsWorld.ray_cast` uses it whenever the world is eligible (no collision
meshes) and falls back to pybullet otherwise.

Matched pybullet semantics (checked against `rayTestBatch` in tests/unit/runtime/test_raycast.py):
- a ray that starts inside a box does not hit that box (it may hit others);
- the ground plane is hit from either side, by segments that strictly cross it;
- hits are reported as the fraction of the segment start → end, endpoints included.
Rays that graze an edge or a face exactly (measure zero) may differ.
"""

from __future__ import annotations

import numpy as np


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
    hits), and the plane is tested on the rays that meet a box only, with the same
    arithmetic (a lidar scan's rays mostly end on the ground or nowhere).
    """
    n, m = len(starts), len(centres)
    best = np.full(n, np.inf)
    index = np.full(n, -1, dtype=np.int64)
    seg = ends - starts
    if n and m:
        rays, boxes = _candidates(starts, seg, centres, rotations, half_extents)
        if len(rays):
            t = _slab(starts[rays] - centres[boxes], seg[rays], rotations[boxes], half_extents[boxes])
            hit = np.isfinite(t)
            rays, boxes, t = rays[hit], boxes[hit], t[hit]
        if len(rays):
            # The nearest hit per ray: sort by (ray, t) and keep each ray's first.
            order = np.lexsort((t, rays))
            rays, boxes, t = rays[order], boxes[order], t[order]
            first = np.r_[True, rays[1:] != rays[:-1]]
            best[rays[first]] = t[first]
            index[rays[first]] = boxes[first]
    if plane_z is not None and n:
        rays = slice(None) if plane_hits else np.flatnonzero(index >= 0)
        above_start, above_end = starts[rays, 2] - plane_z, ends[rays, 2] - plane_z
        with np.errstate(divide="ignore", invalid="ignore"):
            t = above_start / (above_start - above_end)
        # Strictly crossing, as Bullet's triangle ray test: an endpoint on the plane is no hit.
        closer = (above_start * above_end < 0.0) & (t < best[rays])
        if plane_hits:
            best[closer] = t[closer]
            index[closer] = m
        else:
            index[rays[closer]] = -1
    frac = np.where(index >= 0, best, 1.0)
    return index, frac


def _candidates(starts, seg, centres, rotations, half_extents):
    """(ray, box) index pairs whose segment meets the box's bounding sphere.

    A scan's rays mostly share one origin and each box covers a few of them, so the
    exact test runs on a small fraction of the ray × box pairs.
    """
    radius2 = (half_extents ** 2).sum(axis=1)
    # (seg * seg).sum(axis=1) with the same bits ((x² + y²) + z², in numpy's order) in a
    # fifth of the time: a reduction over rows of 3 is slow, whole-column operations are not.
    len2 = (seg[:, 0] * seg[:, 0] + seg[:, 1] * seg[:, 1] + seg[:, 2] * seg[:, 2])[:, None]
    if (starts == starts[0]).all():  # one origin (a lidar scan): (3,) vectors, not (N, 3)
        rel = centres - starts[0]
        # A box around the origin is never hit (pybullet ignores the box a ray starts in):
        # the ego's own body, with the sensor mounted inside it.
        local = np.einsum("kji,kj->ki", rotations, rel)
        keep = ~np.all(np.abs(local) < half_extents, axis=1)
        # Boxes beyond the longest ray's reach (their bounding spheres included) are never
        # met: in dense traffic most of them, and the (rays x boxes) products below shrink.
        reach = np.sqrt(len2.max()) + np.sqrt(radius2)
        keep &= (rel * rel).sum(axis=1) <= reach * reach * (1.0 + 1e-6) + 1e-6
        rel, radius2 = rel[keep], radius2[keep]
        box_ids = np.flatnonzero(keep)
        proj = seg @ rel.T  # (N, K): seg · (centre - start)
        d2 = (rel * rel).sum(axis=1)[None, :]
    else:
        box_ids = np.arange(len(centres))
        proj = seg @ centres.T - (seg * starts).sum(axis=1)[:, None]
        d2 = ((centres * centres).sum(axis=1)[None, :] - 2.0 * (starts @ centres.T)
              + (starts * starts).sum(axis=1)[:, None])
    with np.errstate(divide="ignore", invalid="ignore"):
        tp = np.clip(proj / len2, 0.0, 1.0)  # closest point of the segment to the centre
    dist2 = d2 - tp * (2.0 * proj - tp * len2)
    # Slack for rounding in the expanded distance: a false candidate only costs a test.
    rays, k = np.nonzero(dist2 <= radius2 * (1.0 + 1e-9) + 1e-9 * (1.0 + d2))
    return rays, box_ids[k]


def _slab(rel_starts, seg, rotations, half_extents):
    """Entry fraction of each segment (start relative to the box centre) into its box, inf
    for a miss or a segment that starts inside (pybullet reports neither)."""
    # Into the box frame: R^T v, as rows.
    o = np.einsum("pji,pj->pi", rotations, rel_starts)
    d = np.einsum("pji,pj->pi", rotations, seg)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / d  # ±inf on an axis-parallel segment: the slab is all or nothing
        t1 = (-half_extents - o) * inv
        t2 = (half_extents - o) * inv
    t_near = np.minimum(t1, t2).max(axis=1)
    t_far = np.maximum(t1, t2).min(axis=1)
    hit = (t_near <= t_far) & (t_near >= 0.0) & (t_near <= 1.0)
    return np.where(hit, t_near, np.inf)
