"""Labelled lidar scans generated from the twin itself, for training and evaluating the detector.

A scene is a stretch of road (straight or curved, 1-4 lanes in the ego's direction, 0-3
beside them, often oncoming) with box vehicles of car and truck sizes in the lanes
(queued at random gaps, some mid lane-change), a few parked at random headings beside
the road, and vulnerable road users: pedestrians on the verges and crossing the lanes,
cyclists along the road's edge and crossing. Every object carries its class (`CLASSES`).
The ego sits in one of its lanes; the scan comes from the runtime's own `Lidar` class
casting rays into a pybullet world built like the runtime's (same box bodies, same ground
plane), so the detector is trained on exactly the points it will see.

Each sample keeps the points in the vehicle frame (mapped with the *nominal* extrinsics,
as the stack does) and the ground-truth boxes in the vehicle frame with their lidar hit
counts. `yaw_shift_rad` moves the *actual* mount, as the `shift` fault does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from addt_dsl import units
from addt_dsl.stack.bev_grid import CLASSES, DETECTOR_LIDAR, GRID, sensor_points_to_vehicle
from addt_dsl.vehicles import CAR, VEHICLES

LANE_WIDTH_M = 3.5
EGO_SIZE = (CAR.length_m, CAR.width_m, CAR.height_m)
# Body pool: (kind, length, width, height, count), the bodies the runtime gives its car,
# truck, pedestrian and cyclist actors (addt_dsl.vehicles). The detector learns these
# shapes, which is what lets it place a box's centre from the one face the lidar sees.
POOL = tuple((kind, VEHICLES[kind].length_m, VEHICLES[kind].width_m, VEHICLES[kind].height_m, count)
             for kind, count in (("car", 48), ("truck", 14), ("pedestrian", 12), ("cyclist", 6)))
PARK_X0 = 1.0e4  # unused bodies wait far outside the lidar's range


@dataclass
class Sample:
    points: np.ndarray  # (N, 3) float32, vehicle frame via nominal extrinsics [m]
    sensor_xy: tuple[float, float]  # nominal sensor position in the vehicle frame [m]
    boxes: np.ndarray  # (M, 5) x, y, heading, length, width in the vehicle frame
    hits: np.ndarray  # (M,) lidar returns on each box
    lidar: str  # "RAYSxCHANNELS", e.g. "360x1"
    classes: np.ndarray  # (M,) index into bev_grid.CLASSES


class _ScanWorld:
    """The runtime's pybullet world with a fixed pool of vehicle bodies, posed per scene."""

    def __init__(self):
        from addt_dsl.runtime.world import PhysicsWorld

        self.physics = PhysicsWorld()
        # Scans come from pybullet's rayTestBatch, as when the shipped weights were made:
        # `train --seed 0` reproduces them bit for bit. The loop's exact numpy casts agree
        # with it to 1e-14 m on 99.95 % of rays and within a few mm on the rest
        # (runtime/raycast.py), but a trained network amplifies any difference.
        self.physics.analytic_rays = False
        self.physics.add_box("ego", *EGO_SIZE)
        self.pool: list[tuple[str, str, float, float, float]] = []  # (body name, kind, l, w, h)
        for kind, length, width, height, count in POOL:
            for k in range(count):
                name = f"{kind}_{length}_{k}"
                self.physics.add_box(name, length, width, height)
                self.pool.append((name, kind, length, width, height))
        self.pose = (0.0, 0.0, 0.0, 0.0)
        self.body_index = {self.physics.bodies[p[0]]: i for i, p in enumerate(self.pool)}

    # The two queries `Lidar.capture` makes of the runtime.
    def ego_pose(self):
        return self.pose

    def ray_cast(self, starts, ends):
        return self.physics.ray_cast(starts, ends, ignore="ego")

    def close(self):
        self.physics.close()


def _road_point(kappa: float, s: float, t: float) -> tuple[float, float, float]:
    """(x, y, heading) of road coordinates (s, t) on an arc of curvature `kappa` through the origin."""
    th = kappa * s
    if abs(kappa) < 1e-9:
        x, y = s, 0.0
    else:
        x, y = math.sin(th) / kappa, (1.0 - math.cos(th)) / kappa
    return x - t * math.sin(th), y + t * math.cos(th), th


road_point = _road_point  # public for the camera data (camera_train builds the same roads)


def _overlaps(box, placed, margin: float) -> bool:
    from addt_dsl.runtime.world import box_separation

    x, y, _, length, width = box
    reach = 0.5 * math.hypot(length, width)
    for other in placed:
        d = math.hypot(other[0] - x, other[1] - y)
        if d > reach + 0.5 * math.hypot(other[3], other[4]) + margin:
            continue
        if box_separation(box, other) < margin:
            return True
    return False


CYCLISTS_PER_SCENE = 1.2  # mean of the Poisson count of cyclists tried per scene (the pool holds 6)


def sample_scene(rng: np.random.Generator, pool, road: tuple[float, int, int] | None = None,
                 ego: list | None = None,
                 cyclists: float = CYCLISTS_PER_SCENE) -> list[tuple[int, float, float, float]]:
    """Poses (pool index, x, y, heading) in the ego's vehicle frame for one random scene.

    `road` = (curvature [1/m], lanes right, lanes left) fixes the road instead of drawing
    it (the camera data renders a road mesh built beforehand); `ego`, if given, receives
    the ego's pose (x, y, heading) in the road's frame (the arc through the origin).
    `cyclists`: mean number of cyclists tried (training may ask for more than the
    default, which the held-out evaluation set keeps)."""
    if road is None:
        kappa = float(rng.choice([0.0, rng.uniform(-0.004, 0.004)]))
        n_right = int(rng.integers(1, 5))
        n_left = int(rng.integers(0, 4))
    else:
        kappa, n_right, n_left = float(road[0]), int(road[1]), int(road[2])
    oncoming = rng.random() < 0.7
    ego_lane = int(rng.integers(0, n_right))
    ego_t = -(ego_lane + 0.5) * LANE_WIDTH_M + rng.normal(0.0, 0.3)
    ego_yaw = rng.normal(0.0, math.radians(2.0))
    dense = rng.random() < 0.4
    lanes = [(-(k + 0.5) * LANE_WIDTH_M, False) for k in range(n_right)]
    lanes += [((k + 0.5) * LANE_WIDTH_M, oncoming) for k in range(n_left)]
    free = {kind: [i for i, p in enumerate(pool) if p[1] == kind] for kind in CLASSES}
    for idxs in free.values():
        rng.shuffle(idxs)

    def take(kind):
        return free[kind].pop() if free[kind] else None

    ego_box = (0.0, 0.0, 0.0, EGO_SIZE[0], EGO_SIZE[1])
    ex, ey, eh = _road_point(kappa, 0.0, ego_t)
    ego_heading = eh + ego_yaw
    if ego is not None:
        ego[:] = [ex, ey, ego_heading]

    def to_ego(x, y, h):
        return (*_rot(x - ex, y - ey, -ego_heading), h - ego_heading)

    placed: list[tuple[float, float, float, float, float]] = [ego_box]
    out = []
    for t_lane, opposite in lanes:
        s = -78.0 + rng.uniform(0.0, 15.0)
        while s < 78.0:
            kind = "truck" if rng.random() < 0.2 else "car"
            idx = take(kind)
            if idx is None:
                break
            length, width = pool[idx][2], pool[idx][3]
            s_c = s + 0.5 * length
            t = t_lane + rng.normal(0.0, 0.2)
            yaw = rng.normal(0.0, math.radians(1.5))
            if rng.random() < 0.08:  # mid lane change
                side = rng.choice([-1.0, 1.0])
                t += side * rng.uniform(0.3, 1.75)
                yaw += side * math.radians(rng.uniform(2.0, 10.0))
            x, y, h = _road_point(kappa, s_c, t)
            h += yaw + (math.pi if opposite else 0.0)
            box = (*to_ego(x, y, h), length, width)
            if _overlaps(box, placed, 0.3):
                free[kind].append(idx)
            else:
                placed.append(box)
                out.append((idx, box[0], box[1], box[2]))
            gap = rng.uniform(1.5, 12.0) if dense else rng.uniform(8.0, 70.0)
            s = s_c + 0.5 * length + gap
    # Parked and stray vehicles beside the road at any heading.
    edge_right = -n_right * LANE_WIDTH_M
    edge_left = n_left * LANE_WIDTH_M
    for _ in range(int(rng.poisson(2.0))):
        kind = "truck" if rng.random() < 0.15 else "car"
        idx = take(kind)
        if idx is None:
            continue
        side = rng.random() < 0.5
        t = edge_left + rng.uniform(1.5, 12.0) if side else edge_right - rng.uniform(1.5, 12.0)
        x, y, h = _road_point(kappa, rng.uniform(-60.0, 60.0), t)
        box = (*to_ego(x, y, rng.uniform(-math.pi, math.pi)), pool[idx][2], pool[idx][3])
        if _overlaps(box, placed, 0.3):
            free[kind].append(idx)
            continue
        placed.append(box)
        out.append((idx, box[0], box[1], box[2]))
    # Vulnerable road users, placed last (they fit between the vehicles). Pedestrians
    # stand or walk on the verges or cross the lanes at any station; cyclists ride along
    # the edge of the outer lanes (with or against the oncoming side) or cross.
    road_half = {True: edge_left, False: edge_right}
    for kind, mean in (("pedestrian", 3.0), ("cyclist", cyclists)):
        for _ in range(int(rng.poisson(mean))):
            idx = take(kind)
            if idx is None:
                break
            s_c = rng.uniform(-60.0, 60.0)
            mode = rng.random()
            if mode < 0.4:  # crossing the road anywhere between its edges
                t = rng.uniform(edge_right - 1.0, edge_left + 1.0)
                h = rng.choice([-0.5, 0.5]) * math.pi + rng.normal(0.0, math.radians(15.0))
            elif kind == "cyclist" and mode < 0.8:  # riding along an outer lane's edge
                left = n_left > 0 and rng.random() < 0.3
                edge = road_half[left]
                t = edge - (1.0 if left else -1.0) * rng.uniform(0.5, 1.3)
                h = rng.normal(0.0, math.radians(4.0)) + (math.pi if left and oncoming else 0.0)
            else:  # on a verge: walking along it or standing at any heading
                left = rng.random() < 0.5
                t = road_half[left] + (1.0 if left else -1.0) * rng.uniform(0.5, 6.0)
                h = (rng.choice([0.0, math.pi]) + rng.normal(0.0, math.radians(10.0))
                     if rng.random() < 0.6 else rng.uniform(-math.pi, math.pi))
            x, y, road_h = _road_point(kappa, s_c, t)
            box = (*to_ego(x, y, road_h + h), pool[idx][2], pool[idx][3])
            if _overlaps(box, placed, 0.3):
                free[kind].append(idx)
                continue
            placed.append(box)
            out.append((idx, box[0], box[1], box[2]))
    return out


def _rot(x: float, y: float, angle: float) -> tuple[float, float]:
    c, s = math.cos(angle), math.sin(angle)
    return c * x - s * y, s * x + c * y


wrap_angle = units.wrap_angle


class ScanGenerator:
    """Generates `Sample`s; one pybullet world reused across scenes (close it when done)."""

    def __init__(self, seed: int, lidars: tuple[str, ...] = (DETECTOR_LIDAR.config,),
                 lidar_p: tuple[float, ...] | None = None, yaw_shift_rad: float = 0.0,
                 lidar_settings: dict | None = None, cyclists: float = CYCLISTS_PER_SCENE):
        """`lidars` are "RAYSxCHANNELS" configurations of the runtime's `Lidar` (range and
        vertical field of view those of `DETECTOR_LIDAR` unless `lidar_settings` says
        otherwise; other settings at the Lidar's defaults), drawn per scan with `lidar_p`;
        `cyclists` as in `sample_scene`."""
        from addt_dsl.runtime.sensors import Lidar

        self.rng = np.random.default_rng(seed)
        self.world = _ScanWorld()
        base = {"range": DETECTOR_LIDAR.range_m, "vfov": math.radians(DETECTOR_LIDAR.vfov_deg),
                **(lidar_settings or {})}
        self.lidars = {}
        for config in lidars:
            rays, channels = parse_lidar(config)
            self.lidars[config] = Lidar("lidar", {**base, "rays": rays, "channels": channels})
            if yaw_shift_rad:
                self.lidars[config].actual = self.lidars[config].nominal.shifted(yaw=yaw_shift_rad)
        self.configs = tuple(lidars)
        self.lidar_p = lidar_p
        self.cyclists = cyclists

    def close(self):
        self.world.close()

    def sample(self) -> Sample:
        """One random scene, seen from a random world pose with a lidar drawn from `lidars`."""
        rng = self.rng
        poses = sample_scene(rng, self.world.pool, cyclists=self.cyclists)
        world_pose = (rng.uniform(-500.0, 500.0), rng.uniform(-500.0, 500.0), rng.uniform(-math.pi, math.pi))
        config = self.configs[int(rng.choice(len(self.configs), p=self.lidar_p))]
        return self._scan(poses, world_pose, config)

    def scan(self, objects: list[tuple[str, float, float, float]], lidar: str | None = None) -> Sample:
        """Scan a given scene: `objects` are (kind, x, y, heading) in the ego's vehicle frame."""
        free = {kind: [i for i, p in enumerate(self.world.pool) if p[1] == kind] for kind in CLASSES}
        poses = [(free[kind].pop(0), x, y, h) for kind, x, y, h in objects]
        return self._scan(poses, (0.0, 0.0, 0.0), lidar or self.configs[0])

    def _scan(self, poses, world_pose, config: str) -> Sample:
        world = self.world
        pool = world.pool
        # The ego's world pose must not matter to the scan (the grid is in the vehicle frame).
        wx, wy, wh = world_pose
        world.pose = (wx, wy, wh, 0.0)
        phys = world.physics
        phys.set_pose("ego", wx, wy, EGO_SIZE[2] / 2, wh)
        used = set()
        boxes = []
        classes = []
        for idx, x, y, h in poses:
            name, kind, length, width, height = pool[idx]
            classes.append(CLASSES.index(kind))
            gx, gy = _rot(x, y, wh)
            phys.set_pose(name, wx + gx, wy + gy, height / 2, wh + h)
            used.add(idx)
            boxes.append((x, y, units.wrap_angle(h), length, width))
        for idx, (name, _, _, _, height) in enumerate(pool):
            if idx not in used:
                phys.set_pose(name, PARK_X0 + 30.0 * idx, 0.0, height / 2, 0.0)
        lidar = self.lidars[config]
        frame = lidar.capture(world, 0.0)
        hits = np.zeros(len(poses), dtype=np.int64)
        if len(frame.data["hit_body"]):
            row = {idx: k for k, (idx, *_rest) in enumerate(poses)}
            ids, counts = np.unique(frame.data["hit_body"], return_counts=True)
            for body, count in zip(ids.tolist(), counts.tolist()):
                k = row.get(world.body_index.get(body, -1))
                if k is not None:
                    hits[k] = count
        pts = sensor_points_to_vehicle(frame.data["points"], lidar.nominal).astype(np.float32)
        box_arr = np.array(boxes, dtype=np.float64).reshape(-1, 5)
        return Sample(pts, (lidar.nominal.x, lidar.nominal.y), box_arr, hits, config,
                      np.array(classes, dtype=np.int64))


def parse_lidar(config: str) -> tuple[int, int]:
    rays, _, channels = config.partition("x")
    return int(rays), int(channels or 1)


def in_grid(boxes: np.ndarray, spec=GRID) -> np.ndarray:
    """Boxes whose centre lies inside the BEV grid."""
    return ((boxes[:, 0] >= spec.x_min) & (boxes[:, 0] < spec.x_min + spec.nx * spec.cell_m)
            & (boxes[:, 1] >= spec.y_min) & (boxes[:, 1] < spec.y_min + spec.ny * spec.cell_m))


def generate(n: int, seed: int, **kwargs) -> list[Sample]:
    gen = ScanGenerator(seed, **kwargs)
    try:
        return [gen.sample() for _ in range(n)]
    finally:
        gen.close()


def save_samples(path, samples: list[Sample]) -> None:
    """Store scans compactly (npz) so experiments can reuse them without pybullet."""
    npts = np.array([len(s.points) for s in samples])
    nbox = np.array([len(s.boxes) for s in samples])
    np.savez_compressed(
        path, npts=npts, nbox=nbox,
        points=np.concatenate([s.points for s in samples]) if samples else np.zeros((0, 3), np.float32),
        boxes=np.concatenate([s.boxes for s in samples]) if samples else np.zeros((0, 5)),
        hits=np.concatenate([s.hits for s in samples]) if samples else np.zeros(0, np.int64),
        classes=np.concatenate([s.classes for s in samples]) if samples else np.zeros(0, np.int64),
        sensor_xy=np.array([s.sensor_xy for s in samples]), lidar=np.array([s.lidar for s in samples]))


def load_samples(path) -> list[Sample]:
    with np.load(path) as npz:  # each key access decompresses: read every array once
        z = {k: npz[k] for k in npz.files}
    p_off = np.concatenate([[0], np.cumsum(z["npts"])])
    b_off = np.concatenate([[0], np.cumsum(z["nbox"])])
    # Caches from before the class output hold cars and trucks only: the length tells them apart.
    classes = z["classes"] if "classes" in z else (z["boxes"][:, 3] > 8.0).astype(np.int64)
    return [Sample(z["points"][p_off[k]:p_off[k + 1]], tuple(z["sensor_xy"][k].tolist()),
                   z["boxes"][b_off[k]:b_off[k + 1]], z["hits"][b_off[k]:b_off[k + 1]],
                   str(z["lidar"][k]) if "lidar" in z else f"{int(z['rays'][k])}x1",
                   classes[b_off[k]:b_off[k + 1]])
            for k in range(len(z["npts"]))]

