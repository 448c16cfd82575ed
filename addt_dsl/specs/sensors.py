"""Sensors' specs: keyword, settings (rate, extrinsics, model settings), docs and, for the
cameras, the pixels per frame the cost model counts; the implementations are in
`addt_dsl/runtime/sensors.py`."""

from __future__ import annotations

import math

from addt_dsl import units
from addt_dsl.registry import SENSORS, ParamSpec

EXTRINSICS = (
    ParamSpec("x", units.LENGTH, default=1.0, doc="mount position forward of the vehicle centre"),
    ParamSpec("y", units.LENGTH, default=0.0, doc="mount position, left positive"),
    ParamSpec("z", units.LENGTH, default=1.0, doc="mount height above the road"),
    ParamSpec("roll", units.ANGLE, default=0.0, doc="mount roll about the forward axis"),
    ParamSpec("pitch", units.ANGLE, default=0.0, doc="mount pitch; positive tilts the sensor down"),
    ParamSpec("yaw", units.ANGLE, default=0.0, doc="mount yaw; positive turns the sensor left"),
)


class SensorSpec:
    keyword = ""
    params: tuple[ParamSpec, ...] = ()
    doc = ""
    renders = False  # it draws camera images (the world then builds visual shapes)


@SENSORS.register
class Lidar(SensorSpec):
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
    doc = ("Rotating lidar by batched ray casts: exact ray-box intersection in numpy when the world is "
           "boxes on flat ground (runtime/raycast.py), else pybullet rayTestBatch.")

@SENSORS.register
class Gnss(SensorSpec):
    keyword = "gnss"
    params = (
        ParamSpec("rate", units.FREQUENCY, default=10.0, low=0.1, high=100.0, doc="fix rate"),
        ParamSpec("noise", units.LENGTH, default=0.02, low=0.0, high=50.0, doc="position noise (1 sigma)"),
        *EXTRINSICS,
    )
    doc = ("Position fix of the antenna (the mount position on the vehicle) with Gaussian noise; "
           "heading and speed of the vehicle. Omnidirectional: no field of view.")

@SENSORS.register
class Imu(SensorSpec):
    keyword = "imu"
    params = (
        ParamSpec("rate", units.FREQUENCY, default=100.0, low=1.0, high=1000.0, doc="sample rate"),
        ParamSpec("accel_noise", units.ACCELERATION, default=0.05, low=0.0, high=10.0,
                  doc="accelerometer white noise (1 sigma)"),
        ParamSpec("gyro_noise", units.ANGULAR_RATE, default=0.002, low=0.0, high=1.0,
                  doc="gyroscope white noise (1 sigma)"),
        ParamSpec("accel_bias", units.ACCELERATION, default=0.0, low=-5.0, high=5.0,
                  doc="constant accelerometer bias (all axes)"),
        ParamSpec("gyro_bias", units.ANGULAR_RATE, default=0.0, low=-0.5, high=0.5,
                  doc="constant gyroscope bias (all axes)"),
        *(ParamSpec(p.name, p.dim, default={"x": 0.0, "z": 0.5}.get(p.name, p.default), doc=p.doc)
          for p in EXTRINSICS),
    )
    doc = ("Accelerometer (specific force, gravity included) and gyroscope in the sensor frame, "
           "with white noise and bias. Omnidirectional: no field of view.")

@SENSORS.register
class Camera(SensorSpec):
    keyword = "camera"
    renders = True  # the run builds visual road meshes and coloured actors
    params = (
        ParamSpec("rate", units.FREQUENCY, default=10.0, low=0.1, high=60.0, doc="frame rate"),
        ParamSpec("width", None, kind="int", default=320, low=16, high=1920, doc="image width [px]"),
        ParamSpec("height", None, kind="int", default=240, low=16, high=1080, doc="image height [px]"),
        ParamSpec("fov", units.ANGLE, default=math.radians(90.0), low=math.radians(5.0),
                  high=math.radians(170.0), doc="horizontal field of view"),
        ParamSpec("near", units.LENGTH, default=0.1, low=0.01, high=10.0, doc="near clipping distance"),
        ParamSpec("range", units.LENGTH, default=150.0, low=1.0, high=1000.0, doc="far clipping distance"),
        ParamSpec("segmentation", None, kind="word", default="on", choices=("on", "off"),
                  doc="also return the per-pixel body id image"),
        *(ParamSpec(p.name, p.dim, default={"x": 1.0, "z": 1.4}.get(p.name, p.default), doc=p.doc)
          for p in EXTRINSICS),
    )
    doc = ("Pinhole camera rendered headless by pybullet's TinyRenderer: RGB image (uint8, HxWx3), "
           "metric depth and per-pixel body ids. Cost grows with pixels; see docs/twin.md.")
    @staticmethod
    def pixels_per_frame(settings: dict) -> float:
        """Pixels rendered per frame (the compile-time cost estimate counts them)."""
        return float(settings["width"]) * float(settings["height"])

@SENSORS.register
class CameraRig(SensorSpec):
    keyword = "camera_rig"
    renders = True
    params = (
        ParamSpec("rate", units.FREQUENCY, default=10.0, low=0.1, high=60.0, doc="frame rate (all cameras)"),
        ParamSpec("cameras", None, kind="int", default=6, low=1, high=12,
                  doc="cameras, evenly spread in yaw from the mount's yaw"),
        ParamSpec("width", None, kind="int", default=128, low=16, high=1920, doc="image width per camera [px]"),
        ParamSpec("height", None, kind="int", default=40, low=16, high=1080, doc="image height per camera [px]"),
        ParamSpec("fov", units.ANGLE, default=math.radians(64.0), low=math.radians(5.0),
                  high=math.radians(170.0), doc="horizontal field of view per camera"),
        ParamSpec("near", units.LENGTH, default=0.1, low=0.01, high=10.0, doc="near clipping distance"),
        ParamSpec("range", units.LENGTH, default=150.0, low=1.0, high=1000.0, doc="far clipping distance"),
        *(ParamSpec(p.name, p.dim, default={"x": 0.0, "z": 1.5}.get(p.name, p.default), doc=p.doc)
          for p in EXTRINSICS),
    )
    doc = ("Multi-camera rig (the paper's surround view): `cameras` pinhole cameras around one mount, "
           "rendered like `camera` (RGB only: images uint8, cameras x H x W x 3). For "
           "`perception camera_bev`.")
    @staticmethod
    def pixels_per_frame(settings: dict) -> float:
        """Pixels rendered per frame, all cameras (the compile-time cost estimate counts them)."""
        return float(settings["cameras"]) * float(settings["width"]) * float(settings["height"])
