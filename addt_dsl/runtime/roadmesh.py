"""Road surfaces as geometry: triangle meshes for the renderer, ground for elevated roads.

Pure numpy (the pybullet side is `world.PhysicsWorld.add_mesh`). A road becomes:

* a **surface**: per lane section, a triangulated strip along s whose columns are the
  lane borders, at the road's elevation z(s) (superelevation is ignored, like the
  road package does for t); one mesh per surface class (driving, shoulder, sidewalk,
  ...) so each class gets its colour;
* **markings**: thin strips 2 cm above the surface, derived from the lane layout
  (OpenDRIVE `roadMark` is not parsed): solid at the edges of the driving band and
  between opposite directions, dashed between lanes of the same direction.

Meshes are cut into chunks of at most `CHUNK_M` along s so no single pybullet shape
grows large. `Elevation` is the sampled z(s) / grade(s) of a road for the loop's hot
path (vehicles follow the road height; the dynamics feel the grade).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from addt_dsl.kernel import kernel

CHUNK_M = 100.0  # mesh chunk length along s [m]
MAX_STEP_M = 4.0  # longest surface sample spacing [m]
MAX_TURN_RAD = 0.02  # heading change between samples: chord error < R * 5e-5
MARK_WIDTH_M = 0.15
MARK_LIFT_M = 0.02  # markings float above the surface (no z-fighting in the renderer)
GROUND_DROP_M = 0.05  # with a camera, the ground plane drops below flat roads (same reason)
DASH_M, GAP_M = 3.0, 6.0

SURFACE_CLASSES = {
    "driving": ("asphalt", (0.22, 0.22, 0.24, 1.0)),
    "shoulder": ("shoulder", (0.36, 0.36, 0.36, 1.0)),
    "sidewalk": ("sidewalk", (0.62, 0.62, 0.60, 1.0)),
    "biking": ("biking", (0.55, 0.30, 0.28, 1.0)),
}
DEFAULT_CLASS = ("shoulder", (0.36, 0.36, 0.36, 1.0))
ROADSIDE_CLASSES = {"none": ("verge", (0.30, 0.42, 0.25, 1.0)), "median": ("verge", (0.30, 0.42, 0.25, 1.0))}
MARKING_RGBA = (0.95, 0.95, 0.95, 1.0)
GROUND_RGBA = (0.33, 0.45, 0.27, 1.0)


@dataclass
class Mesh:
    """Triangles (counter-clockwise seen from above) with one colour; SI metres."""

    name: str
    vertices: np.ndarray  # (n, 3)
    indices: np.ndarray  # (m * 3,) int32
    rgba: tuple[float, float, float, float]

    @property
    def triangles(self) -> int:
        return len(self.indices) // 3

    def area(self) -> float:
        tri = self.vertices[self.indices.reshape(-1, 3)]
        return float(0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum())


@kernel
def elevation_at(z, g, ds, length, s):
    """(z [m], grade [-]) at station `s` of a profile sampled every `ds`, held beyond the ends."""
    u = 0.0 if 0.0 > s else s  # min(max(s, 0.0), length), as the builtins pick
    u = (length if length < u else u) / ds
    if u != u:
        raise ValueError("cannot convert float NaN to integer")  # (int()'s words, as interpreted)
    i = int(u)
    if i > z.size - 2:
        i = z.size - 2
    f = u - i
    return z[i] + f * (z[i + 1] - z[i]), g[i] + f * (g[i + 1] - g[i])


class Elevation:
    """Sampled z(s) [m] and grade dz/ds [-] of one road, for per-step queries."""

    STEP_M = 1.0

    def __init__(self, road):
        self.length = float(road.length)
        n = max(2, int(math.ceil(self.length / self.STEP_M)) + 1)
        s = np.linspace(0.0, self.length, n)
        z = np.asarray(road.elevation_profile(s), dtype=float)
        grade = np.asarray(road.elevation_profile.derivative(s), dtype=float)
        self.flat = not (np.any(z != 0.0) or np.any(grade != 0.0))
        self._ds = s[1] - s[0]
        self._z_a, self._g_a = np.array(z, dtype=float), np.array(grade, dtype=float)  # (`elevation_at`'s)
        self.z_min = float(z.min())

    def at(self, s: float) -> tuple[float, float]:
        """(z [m], grade [-]) at station `s`, held constant beyond the road's ends (the
        kernel `FastRoad.pose_rows` runs over many actors)."""
        if self.flat:
            return 0.0, 0.0
        return elevation_at(self._z_a, self._g_a, self._ds, self.length, s)


# ---------------------------------------------------------------- sampling

def surface_stations(road, s0: float, s1: float) -> np.ndarray:
    """Stations in [s0, s1] fine enough that the strip follows curves and crests."""
    probe = np.linspace(s0, s1, max(2, int(math.ceil((s1 - s0) / 0.5)) + 1))
    kappa = np.abs(np.asarray(road.curvature(probe), dtype=float))
    # Vertical curvature of the profile counts like a horizontal one.
    kappa_z = np.abs(np.gradient(np.asarray(road.elevation_profile.derivative(probe), dtype=float), probe)) \
        if len(probe) > 2 else np.zeros_like(probe)
    step = np.minimum(MAX_STEP_M, MAX_TURN_RAD / np.maximum(np.maximum(kappa, kappa_z), 1e-12))
    stations = [s0]
    # Walk the probe grid, emitting a station whenever the local step allows.
    next_s = s0 + step[0]
    for s, st in zip(probe[1:], step[1:]):
        next_s = min(next_s, stations[-1] + st)
        if s >= next_s - 1e-9:
            stations.append(float(s))
            next_s = s + st
    if stations[-1] < s1 - 1e-9:
        stations.append(float(s1))
    return np.asarray(stations)


def _columns(road, section, s: np.ndarray):
    """Border t of every lane of a section, left-outer to right-outer: (n_borders, n_s),
    and the lane id between consecutive borders."""
    ds = s - section.s0
    offset = np.asarray(road.offset_profile(s), dtype=float)
    left = section.side_borders(1, ds, offset)  # rows: centre, lane 1 outer, lane 2 outer, ...
    right = section.side_borders(-1, ds, offset)
    borders = np.concatenate([left[::-1], right[1:]], axis=0)
    ids = [lane.id for lane in reversed(section.left)] + [lane.id for lane in section.right]
    return borders, ids


def _world(road, s: np.ndarray, t: np.ndarray, lift: float = 0.0) -> np.ndarray:
    """World xyz of road coordinates; `s` (n,), `t` (..., n)."""
    x, y, h = road.reference_pose(s)
    z = np.asarray(road.elevation_profile(s), dtype=float) + lift
    t = np.asarray(t, dtype=float)
    return np.stack(np.broadcast_arrays(x - np.sin(h) * t, y + np.cos(h) * t, np.broadcast_to(z, t.shape)), axis=-1)


def _chunks(road):
    """(section, s0, s1) pieces of at most CHUNK_M, never spanning two lane sections."""
    for k, sec in enumerate(road.sections):
        end = road.sections[k + 1].s0 if k + 1 < len(road.sections) else road.length
        start = max(0.0, sec.s0)
        end = min(end, road.length)
        n = max(1, int(math.ceil((end - start) / CHUNK_M - 1e-9)))
        edges = np.linspace(start, end, n + 1)
        for a, b in zip(edges[:-1], edges[1:]):
            if b - a > 1e-6:
                yield sec, float(a), float(b)


# ---------------------------------------------------------------- surface

def surface_meshes(road) -> list[Mesh]:
    """The road surface as coloured meshes, one per (chunk, surface class)."""
    out: list[Mesh] = []
    for ci, (sec, a, b) in enumerate(_chunks(road)):
        s = surface_stations(road, a, b)
        borders, ids = _columns(road, sec, s)
        n_s = len(s)
        verts = _world(road, s, borders).reshape(-1, 3)  # row j = border j, column i = station i
        by_class: dict[tuple, list[np.ndarray]] = {}
        for j, lane_id in enumerate(ids):
            width = np.abs(borders[j + 1] - borders[j])
            if float(width.max()) < 1e-6:
                continue
            lane_type = sec.lane(lane_id).type
            cls = SURFACE_CLASSES.get(lane_type) or ROADSIDE_CLASSES.get(lane_type) or DEFAULT_CLASS
            # Quad between borders j (left) and j+1 (right) from station i to i+1, as two
            # triangles counter-clockwise seen from above.
            i = np.arange(n_s - 1)
            left0, left1 = j * n_s + i, j * n_s + i + 1
            right0, right1 = (j + 1) * n_s + i, (j + 1) * n_s + i + 1
            tris = np.stack([right0, right1, left1, right0, left1, left0], axis=1).reshape(-1, 3)
            by_class.setdefault(cls, []).append(tris)
        for (name, rgba), tris in by_class.items():
            out.append(_compact(f"{road.id}/{ci}/{name}", verts, np.concatenate(tris), rgba))
    return out


def _compact(name: str, verts: np.ndarray, tris: np.ndarray, rgba) -> Mesh:
    used, inverse = np.unique(tris.ravel(), return_inverse=True)
    return Mesh(name, verts[used], inverse.astype(np.int32), tuple(rgba))


# ---------------------------------------------------------------- markings

@dataclass(frozen=True)
class MarkingLine:
    """One marking along a lane border: the border index of the section's column list."""

    border: int
    dashed: bool


def marking_lines(road, section) -> list[MarkingLine]:
    """Which lane borders of a section carry a marking, solid or dashed."""
    _, ids = _columns(road, section, np.array([section.s0]))
    driving = [section.lane(i).type == "driving" for i in ids]
    lines = []
    for border in range(len(ids) + 1):
        left_drive = border > 0 and driving[border - 1]
        right_drive = border < len(ids) and driving[border]
        if not (left_drive or right_drive):
            continue
        if left_drive and right_drive:
            same = road.travel_direction(ids[border - 1]) == road.travel_direction(ids[border])
            lines.append(MarkingLine(border, dashed=same))
        else:
            lines.append(MarkingLine(border, dashed=False))  # edge of the driving band
    return lines


def marking_meshes(road) -> list[Mesh]:
    """Lane markings as thin strips, one mesh per chunk."""
    out: list[Mesh] = []
    half = 0.5 * MARK_WIDTH_M
    for ci, (sec, a, b) in enumerate(_chunks(road)):
        lines = marking_lines(road, sec)
        if not lines:
            continue
        verts_all, tris_all, base = [], [], 0
        for line in lines:
            for s in _marking_runs(road, sec, a, b, line.dashed):
                borders, _ = _columns(road, sec, s)
                t = borders[line.border]
                if float(np.abs(borders[0] - borders[-1]).max()) < 1e-6:
                    continue
                v = _world(road, s, np.stack([t + half, t - half]), MARK_LIFT_M).reshape(-1, 3)
                n = len(s)
                i = np.arange(n - 1)
                left0, left1, right0, right1 = i, i + 1, n + i, n + i + 1
                tris = np.stack([right0, right1, left1, right0, left1, left0], axis=1).reshape(-1) + base
                verts_all.append(v)
                tris_all.append(tris)
                base += len(v)
        if verts_all:
            out.append(Mesh(f"{road.id}/{ci}/markings", np.concatenate(verts_all),
                            np.concatenate(tris_all).astype(np.int32), MARKING_RGBA))
    return out


def _marking_runs(road, sec, a: float, b: float, dashed: bool):
    """Station arrays of the painted runs of one line within [a, b]."""
    if not dashed:
        yield surface_stations(road, a, b)
        return
    period = DASH_M + GAP_M
    # Dashes are phased on the section start so they continue across chunks.
    k0 = math.floor((a - sec.s0) / period)
    start = sec.s0 + k0 * period
    while start < b:
        lo, hi = max(start, a), min(start + DASH_M, b)
        if hi - lo > 0.05:
            yield np.linspace(lo, hi, 3)
        start += period


def ground_mesh(networks, z: float, margin_m: float = 300.0, tile_m: float = 200.0) -> Mesh:
    """Flat terrain under all roads (their bounding box plus `margin_m`), in square tiles
    (the renderer clips small triangles more gracefully than one huge quad)."""
    lo, hi = np.full(2, np.inf), np.full(2, -np.inf)
    for net in networks:
        for road in net.roads.values():
            x, y, _ = road.reference_pose(np.linspace(0.0, road.length, 64))
            pts = np.stack([x, y], axis=1)
            lo, hi = np.minimum(lo, pts.min(axis=0)), np.maximum(hi, pts.max(axis=0))
    lo, hi = lo - margin_m, hi + margin_m
    nx, ny = (max(1, int(math.ceil(v))) for v in (hi - lo) / tile_m)
    gx, gy = np.meshgrid(np.linspace(lo[0], hi[0], nx + 1), np.linspace(lo[1], hi[1], ny + 1))
    verts = np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, z)], axis=1)
    i, j = np.meshgrid(np.arange(nx), np.arange(ny))
    a = (j * (nx + 1) + i).ravel()
    tris = np.stack([a, a + 1, a + nx + 2, a, a + nx + 2, a + nx + 1], axis=1).ravel()
    return Mesh("ground", verts, tris.astype(np.int32), GROUND_RGBA)


@dataclass
class SceneInfo:
    """What `build_scene` put into the physics world."""

    elevated: bool = False
    visual_triangles: int = 0
    collision_triangles: int = 0
    bodies: int = 0


def build_scene(physics, networks) -> SceneInfo:
    """Add the roads to a `PhysicsWorld`.

    Visual meshes (surface, markings, ground) only if the world is visual (a camera is
    fitted). Elevated roads (any non-zero elevation) get their surface as collision
    trimeshes, so lidar rays meet crests, and the infinite ground plane moves below the
    lowest road; flat roads keep the plane as their only collision surface.
    """
    info = SceneInfo()
    roads = [road for net in networks for road in net.roads.values()]
    elevations = {id(road): Elevation(road) for road in roads}
    info.elevated = any(not e.flat for e in elevations.values())
    if not (physics.visual or info.elevated):
        return info
    # The plane sits under the road surfaces so the renderer never z-fights them.
    z_floor = min(e.z_min for e in elevations.values()) - 0.5 if info.elevated else -GROUND_DROP_M
    for road in roads:
        collide = not elevations[id(road)].flat
        if not (physics.visual or collide):
            continue
        for mesh in surface_meshes(road):
            if physics.add_mesh(mesh, collision=collide) is not None:
                info.bodies += 1
                info.visual_triangles += mesh.triangles if physics.visual else 0
                info.collision_triangles += mesh.triangles if collide else 0
        if physics.visual:
            for mesh in marking_meshes(road):
                physics.add_mesh(mesh)
                info.bodies += 1
                info.visual_triangles += mesh.triangles
    if info.elevated or physics.visual:
        physics.set_ground_height(z_floor)
    if physics.visual:
        # pybullet draws the infinite plane as a ~260 m square around its origin only:
        # hide it and lay terrain under the whole road network instead.
        physics.color_ground((0.0, 0.0, 0.0, 0.0))
        ground = ground_mesh(networks, z_floor)
        physics.add_mesh(ground)
        info.bodies += 1
        info.visual_triangles += ground.triangles
    return info
