"""Sensors, one registered class per DSL keyword.

A sensor has a rate, a field of view and extrinsics (mounting pose on the vehicle); the
fault engine may shift the *actual* extrinsics while the stack keeps using the nominal
ones, which is how misalignment errors arise. Frames carry the capture timestamp.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from addt_dsl import units
from addt_dsl.registry import SENSORS, ParamSpec

EXTRINSICS = (
    ParamSpec("x", units.LENGTH, default=1.0, doc="mount position forward of the vehicle centre"),
    ParamSpec("y", units.LENGTH, default=0.0, doc="mount position, left positive"),
    ParamSpec("z", units.LENGTH, default=1.0, doc="mount height"),
    ParamSpec("roll", units.ANGLE, default=0.0, doc="mount roll"),
    ParamSpec("pitch", units.ANGLE, default=0.0, doc="mount pitch"),
    ParamSpec("yaw", units.ANGLE, default=0.0, doc="mount yaw"),
)


@dataclass
class Extrinsics:
    """Sensor pose in the vehicle frame [m, rad]."""

    x: float = 1.0
    y: float = 0.0
    z: float = 1.0
    roll: float = 0.0
    pitch: float = 0.0
    yaw: float = 0.0

    def shifted(self, **delta: float) -> Extrinsics:
        return Extrinsics(**{k: getattr(self, k) + delta.get(k, 0.0) for k in
                             ("x", "y", "z", "roll", "pitch", "yaw")})


@dataclass
class Frame:
    """One sensor frame. `stamp_s` is when it was captured (faults may skew it)."""

    sensor: str
    stamp_s: float
    data: dict = field(default_factory=dict)


class Sensor:
    keyword = ""
    params: tuple[ParamSpec, ...] = ()
    doc = ""

    def __init__(self, name: str, settings: dict):
        self.name = name
        self.settings = {p.name: settings.get(p.name, p.default) for p in self.params}
        self.period_s = 1.0 / float(self.settings["rate"])
        self.nominal = Extrinsics(**{k: float(self.settings[k]) for k in
                                     ("x", "y", "z", "roll", "pitch", "yaw")})
        self.actual = self.nominal

    def capture(self, world, time_s: float) -> Frame:
        raise NotImplementedError


@SENSORS.register
class Lidar(Sensor):
    keyword = "lidar"
    params = (
        ParamSpec("rate", units.FREQUENCY, default=10.0, low=0.1, high=100.0, doc="scan rate"),
        ParamSpec("rays", None, kind="int", default=360, low=8, high=8192, doc="rays per channel"),
        ParamSpec("channels", None, kind="int", default=1, low=1, high=64, doc="vertical channels"),
        ParamSpec("range", units.LENGTH, default=80.0, low=1.0, high=300.0, doc="max range"),
        ParamSpec("fov", units.ANGLE, default=2 * math.pi, low=0.01, high=2 * math.pi, doc="horizontal field of view"),
        ParamSpec("vfov", units.ANGLE, default=math.radians(10.0), low=0.0, high=math.pi, doc="vertical field of view"),
        *EXTRINSICS,
    )
    doc = "Rotating lidar by batched ray casts (pybullet rayTestBatch)."

    def __init__(self, name, settings):
        super().__init__(name, settings)
        rays, ch = int(self.settings["rays"]), int(self.settings["channels"])
        fov = float(self.settings["fov"])
        az = (np.arange(rays) + 0.5) / rays * fov - fov / 2.0
        el = (np.linspace(-0.5, 0.5, ch) * float(self.settings["vfov"]) if ch > 1 else np.zeros(1))
        az_g, el_g = np.meshgrid(az, el)
        # Unit ray directions in the sensor frame (x forward, y left, z up).
        self._dirs = np.stack([np.cos(el_g) * np.cos(az_g), np.cos(el_g) * np.sin(az_g),
                               np.sin(el_g)], axis=-1).reshape(-1, 3)
        self.range_m = float(self.settings["range"])

    def capture(self, world, time_s):
        pose = world.ego_pose()
        origin, rot = _sensor_world_pose(pose, self.actual)
        dirs = self._dirs @ rot.T
        starts = np.repeat(origin[None, :], len(dirs), axis=0)
        ends = starts + dirs * self.range_m
        hit_ids, fractions = world.ray_cast(starts, ends)
        hit = hit_ids >= 0
        dist = fractions * self.range_m
        # Points in the *sensor* frame: the stack maps them with the nominal extrinsics.
        pts = (self._dirs * dist[:, None])[hit]
        return Frame(self.name, time_s, {"points": pts, "hit_body": hit_ids[hit]})


@SENSORS.register
class Gnss(Sensor):
    keyword = "gnss"
    params = (
        ParamSpec("rate", units.FREQUENCY, default=10.0, low=0.1, high=100.0, doc="fix rate"),
        ParamSpec("noise", units.LENGTH, default=0.02, low=0.0, high=50.0, doc="position noise (1 sigma)"),
        *EXTRINSICS,
    )
    doc = "Position fix with Gaussian noise."

    def capture(self, world, time_s):
        x, y, heading, speed = world.ego_pose()
        rng = world.rng("gnss")
        n = float(self.settings["noise"])
        return Frame(self.name, time_s, {"x": x + rng.normal(0.0, n), "y": y + rng.normal(0.0, n),
                                         "heading": heading, "speed": speed})


def _rotation(roll: float, pitch: float, yaw: float) -> np.ndarray:
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch),
                              math.cos(yaw), math.sin(yaw))
    return np.array([
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ])


def _sensor_world_pose(vehicle_pose, ext: Extrinsics):
    x, y, heading, _ = vehicle_pose
    rot_v = _rotation(0.0, 0.0, heading)
    origin = np.array([x, y, 0.0]) + rot_v @ np.array([ext.x, ext.y, ext.z])
    return origin, rot_v @ _rotation(ext.roll, ext.pitch, ext.yaw)


def sensor_to_vehicle(points: np.ndarray, ext: Extrinsics) -> np.ndarray:
    """Map sensor-frame points into the vehicle frame with extrinsics `ext`."""
    rot = _rotation(ext.roll, ext.pitch, ext.yaw)
    return points @ rot.T + np.array([ext.x, ext.y, ext.z])
