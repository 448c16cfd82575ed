"""The pybullet side of the twin: bodies for actors, ray casts, teardown.

One private pybullet client per run (DIRECT mode, never a GUI), made by `PhysicsWorld`
the first time the run asks pybullet something (a render, a ray cast the analytic caster
cannot answer) and given back when the run ends, so runs share no global state. Actor
bodies are boxes posed from the dynamics each step; the ground is an infinite `GEOM_PLANE`
(plane.urdf is only 200 m wide). Road meshes (runtime.roadmesh) are added as visual shapes
when the run has a camera, and as collision trimeshes when a road is elevated, so lidar
rays meet crests. A run with neither (a lidar over flat roads, ground-truth perception)
never makes a client: its rays are cast analytically (`runtime.raycast`).
"""

from __future__ import annotations

import contextlib
import ctypes
import math
import os
import sys

import numpy as np

from addt_dsl.kernel import kernel
from addt_dsl.runtime import raycast


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


class _Clients:
    """Idle pybullet clients of this process, reset and ready for the next world: a new
    client costs 10-40 ms and its first body 5-25 ms more, a reset one ~1 ms (measured on
    the shared 2 cores). A reset client holds no bodies, shapes or settings (body ids start
    at 0 again, as in a new one), so a world is the same on either. At most `MAX` idle; a
    forked process starts with none (its parent's clients are not its own)."""

    MAX = 16  # the default batch: a sweep's next batch takes them; ~28 MB each held idle

    def __init__(self):
        self.idle: list[int] = []
        self.pid = os.getpid()

    def take(self) -> int | None:
        if self.pid != os.getpid():
            self.idle, self.pid = [], os.getpid()
        return self.idle.pop() if self.idle else None

    def give(self, p, client: int) -> None:
        """Back to the pool, reset; disconnected where the pool is full."""
        if self.pid == os.getpid() and len(self.idle) < self.MAX:
            p.resetSimulation(physicsClientId=client)
            self.idle.append(client)
        else:
            with _quiet_stdout():
                p.disconnect(physicsClientId=client)


CLIENTS = _Clients()

MAX_RAYS_PER_BATCH = 8192
_BOX_GROUP, _HIDDEN_GROUP = 1, 1 << 10  # collision filter groups: actor boxes; one left out of a ray test
SUN_DIRECTION = (0.4, 0.3, 1.0)  # high sun: road markings render bright


class PhysicsWorld:
    """The actors' boxes, the ground and road meshes, and the pybullet client (DIRECT) that
    holds them once something needs it (`p`, `client`).

    Bodies are posed from the dynamics each step (mass 0, never integrated by
    pybullet): the engine serves ray casts (lidar), rendering (camera) and contact
    queries. `visual=False` (no camera in the run) creates no visual shapes at all.
    Body ids are pybullet's: it numbers a new (or reset) client's bodies 0, 1, ... in the
    order they are made, so ids are given here in that order (the ground 0), and the client,
    made later, gets the bodies in the same order (checked).
    """

    def __init__(self, visual: bool = False):
        self._client: int | None = None
        self._p = None
        self.visual = visual
        self._made: list[tuple] = []  # ("box", half, rgba) / ("mesh", mesh, collision): what the client gets
        self.ground = 0
        self._ground_rgba = None
        self.ground_ids: set[int] = {self.ground}
        self._ground_array = np.array([self.ground], dtype=np.int64)
        self.bodies: dict[str, int] = {}
        self.body_names: dict[int, str] = {}
        # What the analytic ray caster needs (runtime.raycast): the boxes' sizes and poses
        # (x, y, z, heading, pitch), mirrored from add_box / set_pose, and the plane height.
        self._box_slot: dict[int, int] = {}
        self._box_half: list[tuple[float, float, float]] = []
        self._box_half_table = np.zeros((0, 3))  # the same, a row per box
        self._box_pose = np.zeros((0, 5))  # a row per box: the loop poses many agents at once
        self._box_ids = np.zeros(0, dtype=np.int64)
        self._hit_body = np.array([self.ground, -1], dtype=np.int64)  # the caster's index -> body id
        self._unsynced = np.zeros(0, dtype=bool)  # slots posed since pybullet last saw them
        # Poses not yet in the table, each with the number of its call (`_flush` writes them in
        # that order): slot -> (call, pose) from `set_pose`, and `set_poses` calls.
        self._pending: dict[int, tuple] = {}
        self._pending_rows: list[tuple] = []
        self._calls = 0
        self._ground_z = 0.0
        self._collision_meshes = 0
        self.analytic_rays = True  # False: always ask pybullet (tests compare the two)

    @property
    def p(self):
        """The pybullet module, the client made if it is not yet."""
        self._connect()
        return self._p

    @property
    def client(self) -> int:
        """This world's pybullet client id (made now if it is not yet)."""
        self._connect()
        return self._client

    @property
    def connected(self) -> bool:
        """Whether this world holds a pybullet client now (made and not yet given back)."""
        return self._client is not None

    def _connect(self) -> None:
        """Make the client and give it every body made so far, in order, posed as last set."""
        if self._client is not None:
            return
        client = CLIENTS.take()
        if client is None:
            with _quiet_stdout():  # (its first import prints a banner too)
                import pybullet as p  # imported here: the compiler must never load pybullet

                client = p.connect(p.DIRECT)
        else:
            import pybullet as p
        self._p, self._client = p, client
        p.setGravity(0, 0, -9.81, physicsClientId=client)
        plane = p.createCollisionShape(p.GEOM_PLANE, physicsClientId=client)
        ground = p.createMultiBody(0, plane, physicsClientId=client)
        if ground != self.ground:
            raise RuntimeError(f"pybullet numbered the ground {ground}, not {self.ground}")
        if self._ground_z != 0.0:
            p.resetBasePositionAndOrientation(ground, (0.0, 0.0, self._ground_z), (0.0, 0.0, 0.0, 1.0),
                                              physicsClientId=client)
        if self._ground_rgba is not None:
            p.changeVisualShape(ground, -1, rgbaColor=list(self._ground_rgba), textureUniqueId=-1,
                                physicsClientId=client)
        for body, made in enumerate(self._made, start=1):
            got = self._make_box(*made[1:]) if made[0] == "box" else self._make_mesh(*made[1:])
            if got != body:
                raise RuntimeError(f"pybullet numbered body {body} as {got}")
        self._unsynced[:] = True  # made where they were first put: pose each as last set

    def _make_box(self, half, rgba) -> int:
        p, client = self._p, self._client
        shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=list(half), physicsClientId=client)
        visual = -1
        if self.visual and rgba is not None:
            visual = p.createVisualShape(p.GEOM_BOX, halfExtents=list(half), rgbaColor=list(rgba),
                                         physicsClientId=client)
        body = p.createMultiBody(0, shape, visual, basePosition=[0, 0, half[2]], physicsClientId=client)
        p.setCollisionFilterGroupMask(body, -1, _BOX_GROUP, -1, physicsClientId=client)
        return body

    def _make_mesh(self, mesh, collision: bool) -> int:
        p, client = self._p, self._client
        verts = mesh.vertices.tolist()
        idx = mesh.indices.tolist()
        col = -1
        if collision:
            col = p.createCollisionShape(p.GEOM_MESH, vertices=verts, indices=idx,
                                         flags=p.GEOM_FORCE_CONCAVE_TRIMESH, physicsClientId=client)
        vis = -1
        if self.visual:
            vis = p.createVisualShape(p.GEOM_MESH, vertices=verts, indices=idx, rgbaColor=list(mesh.rgba),
                                      physicsClientId=client)
        return p.createMultiBody(0, col, vis, physicsClientId=client)

    def _add(self, made: tuple) -> int:
        """A body's id: the next in pybullet's order (made now where the client exists)."""
        self._made.append(made)
        body = len(self._made)
        if self._client is not None:
            got = self._make_box(*made[1:]) if made[0] == "box" else self._make_mesh(*made[1:])
            if got != body:
                raise RuntimeError(f"pybullet numbered body {body} as {got}")
        return body

    def add_box(self, name: str, length: float, width: float, height: float,
                rgba: tuple[float, float, float, float] | None = None) -> int:
        """A box body for an actor; visible to the camera only if `rgba` is given."""
        return self.add_boxes([(name, length, width, height, rgba)])[0]

    def add_boxes(self, boxes: list[tuple]) -> list[int]:
        """`add_box` of each (name, length, width, height, rgba or None) in turn, the box
        table grown once (a run's agents: adding them one by one grew it once each)."""
        bodies, poses = [], []
        for name, length, width, height, rgba in boxes:
            body = self._add(("box", (length / 2, width / 2, height / 2), rgba))
            self.bodies[name] = body
            self.body_names[body] = name
            self._box_slot[body] = len(self._box_half)
            self._box_half.append((length / 2, width / 2, height / 2))
            bodies.append(body)
            poses.append((0.0, 0.0, height / 2, 0.0, 0.0))
        if bodies:
            self._box_half_table = np.array(self._box_half, dtype=np.float64).reshape(-1, 3)
            self._box_pose = np.concatenate([self._box_pose, np.array(poses, dtype=np.float64)])
            self._box_ids = np.concatenate([self._box_ids, np.array(bodies, dtype=np.int64)])
            self._hit_body = np.concatenate([self._box_ids, [self.ground, -1]])
            self._unsynced = np.concatenate([self._unsynced, np.zeros(len(bodies), dtype=bool)])
        return bodies

    def add_mesh(self, mesh, collision: bool = False) -> int | None:
        """A static road mesh: visible (when the world is visual) and/or part of the ground
        for ray casts (`collision`, used for elevated roads). Returns the body id."""
        if not (self.visual or collision) or mesh.triangles == 0:
            return None
        body = self._add(("mesh", mesh, collision))
        self._collision_meshes += collision
        self.ground_ids.add(body)
        self._ground_array = np.array(sorted(self.ground_ids), dtype=np.int64)
        return body

    def set_ground_height(self, z: float) -> None:
        """Move the infinite ground plane (below the lowest road when roads are elevated)."""
        self._ground_z = z
        if self._client is not None:
            self._p.resetBasePositionAndOrientation(self.ground, (0.0, 0.0, z), (0.0, 0.0, 0.0, 1.0),
                                                    physicsClientId=self._client)

    def color_ground(self, rgba) -> None:
        """Plain colour for the ground plane (the renderer draws it checkered by default)."""
        self._ground_rgba = tuple(rgba)
        if self._client is not None:
            self._p.changeVisualShape(self.ground, -1, rgbaColor=list(rgba), textureUniqueId=-1,
                                      physicsClientId=self._client)

    def set_pose(self, name: str, x: float, y: float, z: float, heading: float, pitch: float = 0.0) -> None:
        """Pose a body: yaw `heading`, then `pitch` (nose up positive) [rad].

        pybullet gets the pose only when it is next asked something (`_sync_bodies`): the
        loop poses every body every step, and most steps no sensor looks."""
        # Kept aside until the table is read (`_flush`): a numpy row store costs ~0.5 us,
        # a dict store ~0.05 us, and the loop poses the ego (and few agents) every step.
        self._calls += 1
        self._pending[self._box_slot[self.bodies[name]]] = (self._calls, (x, y, z, heading, pitch))

    def box_poses(self) -> np.ndarray:
        """The box table: a row (x, y, z, heading, pitch) per box, as last posed."""
        if self._pending or self._pending_rows:
            self._flush()
        return self._box_pose

    def _flush(self) -> None:
        """Write the poses `set_pose` and `set_poses` kept aside into the box table in the
        order of their calls."""
        pose, unsynced = self._box_pose, self._unsynced
        rows = self._pending_rows
        i = 0
        for slot, (call, row) in sorted(self._pending.items(), key=lambda item: item[1][0]):
            while i < len(rows) and rows[i][0] < call:
                _put_poses(pose, unsynced, *rows[i][1:])
                i += 1
            pose[slot] = row
            unsynced[slot] = True
        for later in rows[i:]:
            _put_poses(pose, unsynced, *later[1:])
        rows.clear()
        self._pending.clear()

    def set_poses(self, slots: np.ndarray, table: np.ndarray, lo: int, columns: np.ndarray) -> None:
        """`set_pose` of many boxes at once: box `slots[i]` (rows of the box table,
        `box_slots`) at table[columns, lo + i] (columns: the rows of x, y, z, heading and
        pitch in `table`, which the caller leaves as it is from then on), in one kernel call
        (`_put_poses`) when the table is next read: most steps no sensor reads it, and the
        next step's poses of the same slots replace these."""
        self._calls += 1
        rows = self._pending_rows
        if rows and rows[-1][1] is slots:  # (the same slots last time: all its poses are older than these)
            rows[-1] = (self._calls, slots, table, lo, columns)
        else:
            rows.append((self._calls, slots, table, lo, columns))
            if len(rows) > 4:  # (other slots each step: not held without bound)
                self._flush()

    def box_slots(self, names) -> list[int]:
        """The rows of the named bodies in the box table (`set_poses`)."""
        return [self._box_slot[self.bodies[n]] for n in names]

    def _sync_bodies(self) -> None:
        """Hand pybullet the poses set since it was last asked (ray casts, renders)."""
        p, client = self.p, self.client
        if self._pending or self._pending_rows:
            self._flush()
        for slot in np.flatnonzero(self._unsynced).tolist():
            x, y, z, heading, pitch = self._box_pose[slot].tolist()
            hy, hp = 0.5 * heading, -0.5 * pitch  # body y axis points left: nose-up is a negative rotation
            cy, sy = math.cos(hy), math.sin(hy)
            if hp == 0.0:
                quat = (0.0, 0.0, sy, cy)
            else:
                cp, sp = math.cos(hp), math.sin(hp)
                quat = (-sy * sp, cy * sp, sy * cp, cy * cp)
            p.resetBasePositionAndOrientation(int(self._box_ids[slot]), (x, y, z), quat, physicsClientId=client)
        self._unsynced[:] = False

    @property
    def analytic(self) -> bool:
        """Whether ray casts are answered by `runtime.raycast`: the collision world is only
        boxes and the ground plane (no road meshes), which it casts against exactly."""
        return self.analytic_rays and self._collision_meshes == 0

    def ray_cast(self, starts: np.ndarray, ends: np.ndarray, ignore: str | None = None):
        """Batched rays; returns (body ids, -1 for none, the ground or the ignored body; hit fractions).
        `starts` may be one origin broadcast to every ray (`np.broadcast_to`: a scan)."""
        if self.analytic:  # the caster drops ground hits and the ignored body's itself
            return self._ray_cast_analytic(starts, ends, ground_hits=False, ignore=ignore)
        ids, frac = self._ray_cast_pybullet(starts, ends)
        ground = np.isin(ids, self._ground_array) if len(self._ground_array) > 1 else ids == self.ground
        ids[ground] = -1
        if ignore is not None:
            ids[ids == self.bodies[ignore]] = -1
        frac[ids < 0] = 1.0
        return ids, frac

    def _ray_cast_analytic(self, starts: np.ndarray, ends: np.ndarray, ground_hits: bool = True,
                           ignore: str | None = None):
        """`raycast.cast` on the boxes and the ground plane; with `ground_hits=False` a ray
        whose first hit is the ground reports -1 (no hit), as one whose first hit is the
        body named `ignore`."""
        centres, rotations, half, plane_z, slot, hit_body = self.ray_scene(ignore)
        index, frac = raycast.cast(starts, ends, centres, rotations, half, plane_z, plane_hits=ground_hits,
                                   ignore=slot)
        return hit_body[index], frac

    def ray_scene(self, ignore: str | None = None) -> tuple | None:
        """What the analytic caster reads of this world, for a kernel that casts itself
        (`sensors._scan`): the boxes' centres (M x 3), rotations (M x 3 x 3) and half extents
        [m], the ground plane's height [m], the box of body `ignore` (-1: none), and the body
        id of each caster index (index M: the ground; the last entry -1). None where rays
        must go to pybullet (road meshes in the collision world, or `analytic_rays` off)."""
        if not self.analytic:
            return None
        pose = self.box_poses()
        centres = np.ascontiguousarray(pose[:, :3])
        rotations = raycast.box_rotations(np.ascontiguousarray(pose[:, 3]), np.ascontiguousarray(pose[:, 4]))
        slot = -1 if ignore is None else self._box_slot[self.bodies[ignore]]
        return centres, rotations, self._box_half_table, float(self._ground_z), slot, self._hit_body

    def _ray_cast_pybullet(self, starts, ends):
        self._sync_bodies()
        if len(starts) <= MAX_RAYS_PER_BATCH:
            results = self.p.rayTestBatch(starts, ends, physicsClientId=self.client)
        else:  # pybullet refuses batches of 16384 rays or more
            results = []
            for i in range(0, len(starts), MAX_RAYS_PER_BATCH):
                results.extend(self.p.rayTestBatch(starts[i:i + MAX_RAYS_PER_BATCH], ends[i:i + MAX_RAYS_PER_BATCH],
                                                   physicsClientId=self.client))
        ids_t, _, frac_t, _, _ = zip(*results) if results else ((), (), (), (), ())
        ids, frac = np.array(ids_t, dtype=np.int64), np.array(frac_t, dtype=np.float64)
        # Bullet's convex cast sometimes reports the box a ray starts in, at fraction 0
        # (depending on where inside and which way: a lidar mounted low in the ego's box
        # lost ~17 % of its rays). A ray passes through the box it starts in, as it does
        # in most directions: cast those rays again with that box filtered out.
        p, hidden = self.p, []
        stuck = np.flatnonzero((frac == 0.0) & np.isin(ids, self._box_ids))
        while len(stuck):  # a ray may start inside several (overlapping) boxes
            for body in np.unique(ids[stuck]).tolist():
                p.setCollisionFilterGroupMask(body, -1, _HIDDEN_GROUP, -1, physicsClientId=self.client)
                hidden.append(body)
            again = p.rayTestBatch(starts[stuck], ends[stuck], collisionFilterMask=-1 ^ _HIDDEN_GROUP,
                                   physicsClientId=self.client)
            ids[stuck] = [r[0] for r in again]
            frac[stuck] = [r[2] for r in again]
            stuck = stuck[(frac[stuck] == 0.0) & np.isin(ids[stuck], self._box_ids)]
        for body in hidden:
            p.setCollisionFilterGroupMask(body, -1, _BOX_GROUP, -1, physicsClientId=self.client)
        return ids, frac

    def render(self, width: int, height: int, view: list[float], projection: list[float],
               segmentation: bool = True):
        """Headless render (TinyRenderer): (rgb uint8 HxWx3, z-buffer float32 HxW, body ids int32 HxW | None)."""
        self._sync_bodies()
        p = self.p
        flags = 0 if segmentation else p.ER_NO_SEGMENTATION_MASK
        _, _, rgba, depth, seg = p.getCameraImage(width, height, view, projection, shadow=0,
                                                  lightDirection=SUN_DIRECTION,
                                                  renderer=p.ER_TINY_RENDERER, flags=flags,
                                                  physicsClientId=self.client)
        rgb = np.ascontiguousarray(np.reshape(np.asarray(rgba, dtype=np.uint8), (height, width, 4))[:, :, :3])
        zbuf = np.reshape(np.asarray(depth, dtype=np.float32), (height, width))
        ids = np.reshape(np.asarray(seg, dtype=np.int32), (height, width)) if segmentation else None
        return rgb, zbuf, ids

    def close(self) -> None:
        if self._client is not None:
            CLIENTS.give(self._p, self._client)
            self._client = None


def box_corners(x, y, heading, length, width) -> np.ndarray:
    c, s = math.cos(heading), math.sin(heading)
    hl, hw = length / 2, width / 2
    local = ((hl, hw), (hl, -hw), (-hl, -hw), (-hl, hw))
    return np.array([(x + c * a - s * b, y + s * a + c * b) for a, b in local])


def box_separation(a: tuple, b: tuple) -> float:
    """Separation of two oriented boxes (x, y, heading, length, width) along the best axis.

    Positive: the boxes are apart by at least this much [m]; zero or negative: they
    overlap (separating axis theorem over the four edge normals). On each axis u the gap
    is |d . u| minus both boxes' projected half-extents, which equals projecting all
    eight corners (`separation`, compiled: the clearances kernel calls it too).
    """
    xa, ya, ha, la, wa = a
    xb, yb, hb, lb, wb = b
    # (floats: the compiled kernel keeps one signature; int * float converts the int alike)
    return separation(float(xb - xa), float(yb - ya), math.cos(ha), math.sin(ha), math.cos(hb), math.sin(hb),
                      float(la), float(wa), float(lb), float(wb))


@kernel
def separation(dx, dy, ca, sa, cb, sb, la, wa, lb, wb):
    """`box_separation` from the centres' offset (dx, dy) [m], each box's heading cosine and
    sine and its length and width [m]: the largest of the four axes' gaps, taken as
    `max(a, b, c, d)` takes it (a later value replaces the one kept only when greater). A
    kernel: the clearances (`collision`) call it compiled, `box_separation` too."""
    cos_d = abs(ca * cb + sa * sb)  # |cos(hb - ha)|
    sin_d = abs(sa * cb - ca * sb)  # |sin(hb - ha)|
    la, wa, lb, wb = 0.5 * la, 0.5 * wa, 0.5 * lb, 0.5 * wb
    gap = abs(dx * ca + dy * sa) - (la + lb * cos_d + wb * sin_d)
    other = abs(dy * ca - dx * sa) - (wa + lb * sin_d + wb * cos_d)
    if other > gap:
        gap = other
    other = abs(dx * cb + dy * sb) - (lb + la * cos_d + wa * sin_d)
    if other > gap:
        gap = other
    other = abs(dy * cb - dx * sb) - (wb + la * sin_d + wa * cos_d)
    if other > gap:
        gap = other
    return gap


@kernel
def _put_poses(box, unsynced, slots, table, lo, columns):
    """Box slots[i]'s pose (x, y, z, heading, pitch) from table[columns, lo + i]; marked
    for pybullet (`PhysicsWorld._sync_bodies`)."""
    for i in range(slots.size):
        b = slots[i]
        for c in range(5):
            box[b, c] = table[columns[c], lo + i]
        unsynced[b] = True
