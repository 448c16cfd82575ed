"""The camera BEV network's lift: BEV grid cells → camera feature pixels (numpy).

As Fast-BEV's "fast ray" transform: every cell of the BEV grid (`bev_grid.GRID`), at a
few heights above the road (`LIFT_HEIGHTS_M`), is projected through the *nominal*
intrinsics and extrinsics of the rig into the camera that sees it most centrally; the
cell takes that camera's feature vector at that pixel (of the encoder's output, which
has `FEATURE_STRIDE` times fewer pixels, 1: as many). Depth is not estimated: a feature lands on
every cell along its ray, and the BEV network learns where along the ray the object
is (where the features at road height change from road to object: the object's foot).
The table is computed once per rig; the gather is one index per cell and height.
"""

from __future__ import annotations

import numpy as np

from addt_dsl.kernel import matmul
from addt_dsl.runtime.sensors import rotation
from addt_dsl.stack.bev_grid import GRID, GridSpec

# Above the road [m]: a road user's foot, a pedestrian's or car's body and roof line, a
# truck's body. Which heights of a cell land on an object is what places it along the ray.
LIFT_HEIGHTS_M = (0.2, 0.6, 1.0, 1.5, 2.5)
FEATURE_STRIDE = 1  # full resolution: at 2 the 20-40 m band spans two feature rows
MIN_FORWARD_M = 0.5  # points closer in front of a camera than this are not projected


def lift_table(intrinsics: np.ndarray, extrinsics, width: int, height: int, spec: GridSpec = GRID,
               heights=LIFT_HEIGHTS_M, stride: int = FEATURE_STRIDE) -> np.ndarray:
    """(len(heights), nx, ny) int64 indices into the flattened encoder output of all
    cameras (camera, row, column at 1/`stride`); cells no camera sees get the index
    `cameras * rows * columns` (a zero feature appended by the network).

    `extrinsics`: one object per camera with x, y, z, roll, pitch, yaw (vehicle frame)."""
    fx, fy, cx, cy = intrinsics[0, 0], intrinsics[1, 1], intrinsics[0, 2], intrinsics[1, 2]
    hf, wf = -(-height // stride), -(-width // stride)
    n_cam = len(extrinsics)
    xs = spec.x_min + (np.arange(spec.nx) + 0.5) * spec.cell_m
    ys = spec.y_min + (np.arange(spec.ny) + 0.5) * spec.cell_m
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    out = np.full((len(heights), spec.nx, spec.ny), n_cam * hf * wf, dtype=np.int64)
    for h, z in enumerate(heights):
        best = np.full(gx.shape, -np.inf)
        pts = np.stack([gx, gy, np.full_like(gx, z)], axis=-1)
        for k, ext in enumerate(extrinsics):
            rot = rotation(ext.roll, ext.pitch, ext.yaw)
            p = matmul(pts - np.array([ext.x, ext.y, ext.z]), rot)  # camera frame: forward, left, up
            fwd, left, up = p[..., 0], p[..., 1], p[..., 2]
            with np.errstate(divide="ignore", invalid="ignore"):
                u = cx - fx * left / fwd
                v = cy - fy * up / fwd
            ok = (fwd > MIN_FORWARD_M) & (u >= 0) & (u < width) & (v >= 0) & (v < height)
            # The most central view: the largest cosine to the optical axis.
            centrality = np.where(ok, fwd / np.linalg.norm(p, axis=-1), -np.inf)
            take = centrality > best
            best = np.where(take, centrality, best)
            row = np.clip(np.floor(np.where(ok, v, 0)).astype(np.int64) // stride, 0, hf - 1)
            col = np.clip(np.floor(np.where(ok, u, 0)).astype(np.int64) // stride, 0, wf - 1)
            out[h] = np.where(take, k * hf * wf + row * wf + col, out[h])
    return out


def position_channels(spec: GridSpec = GRID, origin_xy: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """(3, nx, ny) float32: direction (cos, sin) and range / 60 m of each cell from the
    rig, so the translation-equivariant network knows where a cell is (as the lidar
    grid's ray channels)."""
    xs = spec.x_min + (np.arange(spec.nx) + 0.5) * spec.cell_m - origin_xy[0]
    ys = spec.y_min + (np.arange(spec.ny) + 0.5) * spec.cell_m - origin_xy[1]
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    r = np.maximum(np.hypot(gx, gy), 1e-6)
    return np.stack([gx / r, gy / r, r / 60.0]).astype(np.float32)
