"""The pybullet side of the twin: bodies for actors, ray casts, teardown.

One private pybullet client per run (DIRECT mode, never a GUI), created and torn down by
`World`, so runs share no global state. Actor bodies are boxes posed from the dynamics
each step; the ground is an infinite `GEOM_PLANE` (plane.urdf is only 200 m wide).
"""

from __future__ import annotations

import contextlib
import ctypes
import math
import os
import sys

import numpy as np


@contextlib.contextmanager
def _quiet_stdout():
    """Silence C-level stdout/stderr: pybullet prints a build banner on every first connect."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = (os.dup(1), os.dup(2))
    try:
        with open(os.devnull, "w") as devnull:
            os.dup2(devnull.fileno(), 1)
            os.dup2(devnull.fileno(), 2)
            try:
                yield
            finally:
                # C stdio buffers output when it goes to a pipe: flush it into /dev/null.
                ctypes.CDLL(None).fflush(None)
    finally:
        for fd, copy in zip((1, 2), saved):
            os.dup2(copy, fd)
            os.close(copy)


class PhysicsWorld:
    def __init__(self):
        with _quiet_stdout():
            import pybullet as p  # imported here: the compiler must never load pybullet

            self.client = p.connect(p.DIRECT)
        self.p = p
        p.setGravity(0, 0, -9.81, physicsClientId=self.client)
        plane = p.createCollisionShape(p.GEOM_PLANE, physicsClientId=self.client)
        self.ground = p.createMultiBody(0, plane, physicsClientId=self.client)
        self.bodies: dict[str, int] = {}
        self.body_names: dict[int, str] = {}

    def add_box(self, name: str, length: float, width: float, height: float) -> int:
        p = self.p
        shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=[length / 2, width / 2, height / 2],
                                       physicsClientId=self.client)
        body = p.createMultiBody(0, shape, basePosition=[0, 0, height / 2], physicsClientId=self.client)
        self.bodies[name] = body
        self.body_names[body] = name
        return body

    def set_pose(self, name: str, x: float, y: float, z: float, heading: float) -> None:
        half = 0.5 * heading
        self.p.resetBasePositionAndOrientation(self.bodies[name], (x, y, z),
                                               (0.0, 0.0, math.sin(half), math.cos(half)),
                                               physicsClientId=self.client)

    def ray_cast(self, starts: np.ndarray, ends: np.ndarray, ignore: str | None = None):
        """Batched rays; returns (body ids, -1 for none or the ground/ignored body; hit fractions)."""
        results = self.p.rayTestBatch(starts, ends, physicsClientId=self.client)
        ids = np.fromiter((r[0] for r in results), dtype=np.int64, count=len(results))
        frac = np.fromiter((r[2] for r in results), dtype=np.float64, count=len(results))
        ids[ids == self.ground] = -1
        if ignore is not None:
            ids[ids == self.bodies[ignore]] = -1
        frac[ids < 0] = 1.0
        return ids, frac

    def close(self) -> None:
        if self.client is not None:
            with _quiet_stdout():
                self.p.disconnect(physicsClientId=self.client)
            self.client = None


def box_corners(x, y, heading, length, width) -> np.ndarray:
    c, s = math.cos(heading), math.sin(heading)
    hl, hw = length / 2, width / 2
    local = ((hl, hw), (hl, -hw), (-hl, -hw), (-hl, hw))
    return np.array([(x + c * a - s * b, y + s * a + c * b) for a, b in local])


def box_separation(a: tuple, b: tuple) -> float:
    """Separation of two oriented boxes (x, y, heading, length, width) along the best axis.

    Positive: the boxes are apart by at least this much [m]; zero or negative: they
    overlap (separating axis theorem over the four edge normals).
    """
    ca = box_corners(*a)
    cb = box_corners(*b)
    best = -math.inf
    for heading in (a[2], b[2]):
        for axis in ((math.cos(heading), math.sin(heading)), (-math.sin(heading), math.cos(heading))):
            pa = ca @ axis
            pb = cb @ axis
            gap = max(pb.min() - pa.max(), pa.min() - pb.max())
            best = max(best, gap)
    return best
