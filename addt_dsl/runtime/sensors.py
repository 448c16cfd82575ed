"""Sensors: the implementations of the specs in `addt_dsl/specs/sensors.py`.

A sensor has a rate, a field of view and extrinsics (mounting pose on the vehicle); the
fault engine may shift the *actual* extrinsics while the stack keeps using the nominal
ones, which is how misalignment errors arise. Frames carry the capture timestamp.

The vehicle frame: x forward, y left, z up, origin on the road surface under the
vehicle centre; it follows the road's height and grade (pitch). Sensors read the world
through `ego_pose()` (x, y, heading, speed), `ego_frame()` (x, y, z, heading, pitch),
`ego_state()` (the dynamics state), `ray_cast` and `render`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from addt_dsl.kernel import kernel, matmul, matmul_into
from addt_dsl.runtime.raycast import cast_into
from addt_dsl.registry import SENSORS
from addt_dsl.specs import sensors as S

G = 9.81  # [m/s^2]

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
    """One sensor frame. `stamp_s` is when it was captured (faults may skew it).

    What was true at the capture travels with the frame (set by the loop as it captures):
    `ego_pose` (x, y, heading, speed) where the ego was, which a stack maps the frame's
    measurements out with (the pose at the frame's time, as a stack's timestamped transform
    gives it), and `actors`, the ground truth of the bodies a lidar hit then (body id ->
    `actor_by_body`'s answer). A frame that arrives late shows the world as it was.
    """

    sensor: str
    stamp_s: float
    data: dict = field(default_factory=dict)
    ego_pose: tuple | None = None
    actors: dict | None = None


class Sensor(S.SensorSpec):
    def __init__(self, name: str, settings: dict):
        self.name = name
        self.settings = {p.name: settings.get(p.name, p.default) for p in self.params}
        self.period_s = 1.0 / float(self.settings["rate"])
        self.nominal = Extrinsics(**{k: float(self.settings[k]) for k in
                                     ("x", "y", "z", "roll", "pitch", "yaw")})
        self.actual = self.nominal

    def capture(self, world, time_s: float) -> Frame:
        raise NotImplementedError


@SENSORS.implements
class Lidar(S.Lidar, Sensor):

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
        scene = getattr(world, "ray_scene", None)  # (worlds that answer rays only through `ray_cast` lack it)
        scene = scene() if scene is not None else None
        if scene is not None:  # the whole scan in one kernel call, the bits of the calls below
            a = self.actual
            mount = np.array([a.x, a.y, a.z, a.roll, a.pitch, a.yaw])
            pts, bodies = _scan(np.array(_ego_frame(world), dtype=np.float64), mount, self._dirs, self.range_m,
                                *scene)
            return Frame(self.name, time_s, {"points": pts, "hit_body": bodies})
        origin, rot = _sensor_world_pose(_ego_frame(world), self.actual)
        # Every ray from the one origin: a read-only view of it, row after row (no copy).
        origin = np.ascontiguousarray(origin, dtype=np.float64)
        starts = np.ndarray(self._dirs.shape, np.float64, origin, 0, (0, origin.itemsize))
        starts.flags.writeable = False
        hit_ids, fractions = world.ray_cast(starts, _ray_ends(origin, self._dirs, rot, self.range_m))
        # Points in the *sensor* frame: the stack maps them with the nominal extrinsics.
        pts, bodies = _returns(self._dirs, hit_ids, fractions, self.range_m)
        return Frame(self.name, time_s, {"points": pts, "hit_body": bodies})


@kernel
def _ray_ends(origin, dirs, rot, range_m):
    """origin + matmul(dirs, rot.T) * range_m [m], N×3: the sensor-frame directions `dirs`
    turned into the world by `rot` (`kernel.matmul`'s bits), a product, then a sum (numpy's
    bits; numpy pays several us to broadcast the origin over 3-wide rows)."""
    world = np.empty(dirs.shape)
    matmul_into(dirs, rot.T, world)
    ends = np.empty(dirs.shape)
    for i in range(dirs.shape[0]):
        for c in range(3):
            ends[i, c] = origin[c] + world[i, c] * range_m
    return ends


@kernel
def _scan(frame, mount, dirs, range_m, centres, rotations, half, plane_z, ignore, hit_body):
    """A lidar's scan where the world is boxes and a ground plane (`SensorWorld.ray_scene`):
    `Lidar.capture`'s calls in one, their code and bits: the mount's world pose from the
    vehicle frame (x, y, z, heading, pitch) and the mount (x, y, z, roll, pitch, yaw:
    `_sensor_world_pose`), the rays' ends (`_ray_ends`), the first hit of each ray among the
    boxes (`raycast.cast_into` with the ground's hits and box `ignore` dropped; the body ids
    `hit_body[index]`, -1 for none) and the returns (`_returns`)."""
    base, arm = np.empty(3), np.empty(3)
    for c in range(3):
        base[c], arm[c] = frame[c], mount[c]
    rot_v, rot_m = np.empty((3, 3)), np.empty((3, 3))
    _rotation_into(0.0, -frame[4], frame[3], rot_v)
    _rotation_into(mount[3], mount[4], mount[5], rot_m)
    origin, rot = _mount_pose(base, rot_v, arm, rot_m)
    ends = _ray_ends(origin, dirs, rot, range_m)
    n = dirs.shape[0]
    index = np.empty(n, dtype=np.int64)
    frac = np.empty(n)
    cast_into(origin.reshape(1, 3), ends, centres, rotations, half, plane_z, True, False, ignore, index, frac)
    ids = np.empty(n, dtype=hit_body.dtype)
    for i in range(n):
        ids[i] = hit_body[index[i]] if index[i] >= 0 else -1
    return _returns(dirs, ids, frac, range_m)


@kernel
def _returns(dirs, hit_ids, fractions, range_m):
    """The hits of a scan, in ray order: (points, N×3: a hit ray's direction times its
    distance, fraction × range [m]; their body ids) of the rays with a body id >= 0."""
    n = 0
    for i in range(hit_ids.shape[0]):
        if hit_ids[i] >= 0:
            n += 1
    points = np.empty((n, 3))
    bodies = np.empty(n, dtype=hit_ids.dtype)
    j = 0
    for i in range(hit_ids.shape[0]):
        if hit_ids[i] >= 0:
            dist = fractions[i] * range_m
            points[j, 0], points[j, 1], points[j, 2] = dirs[i, 0] * dist, dirs[i, 1] * dist, dirs[i, 2] * dist
            bodies[j] = hit_ids[i]
            j += 1
    return points, bodies


@SENSORS.implements
class Gnss(S.Gnss, Sensor):

    def capture(self, world, time_s):
        x, y, z, heading, pitch = _ego_frame(world)
        _, _, _, speed = world.ego_pose()
        ant, _ = _sensor_world_pose((x, y, z, heading, pitch), self.actual)
        rng = world.rng(self.name)
        n = float(self.settings["noise"])
        return Frame(self.name, time_s, {"x": float(ant[0]) + rng.normal(0.0, n),
                                         "y": float(ant[1]) + rng.normal(0.0, n),
                                         "z": float(ant[2]) + rng.normal(0.0, n),
                                         "heading": heading, "speed": speed})


@SENSORS.implements
class Imu(S.Imu, Sensor):

    def capture(self, world, time_s):
        st = world.ego_state()
        ext = self.actual
        # Specific force and rotation rate at the vehicle centre, vehicle frame.
        pitch = st.pitch
        f = np.array([st.ax_specific, st.ay, G * math.cos(pitch)])
        # Rigid-body lever arm of the mount (planar motion: omega = (0, 0, r)).
        r, r_dot = st.yaw_rate, st.yaw_acc
        f[0] += -r_dot * ext.y - r * r * ext.x
        f[1] += r_dot * ext.x - r * r * ext.y
        omega = np.array([0.0, 0.0, r])
        rot = rotation(ext.roll, ext.pitch, ext.yaw)
        rng = world.rng(self.name)
        s = self.settings
        accel = matmul(rot.T, f) + float(s["accel_bias"]) + rng.normal(0.0, float(s["accel_noise"]), 3)
        gyro = matmul(rot.T, omega) + float(s["gyro_bias"]) + rng.normal(0.0, float(s["gyro_noise"]), 3)
        return Frame(self.name, time_s, {"accel": accel, "gyro": gyro})


@SENSORS.implements
class Camera(S.Camera, Sensor):

    def __init__(self, name, settings):
        super().__init__(name, settings)
        self.width, self.height = int(self.settings["width"]), int(self.settings["height"])
        self.near, self.far = float(self.settings["near"]), float(self.settings["range"])
        aspect = self.width / self.height
        fov_h = float(self.settings["fov"])
        self.fov_v = 2.0 * math.atan(math.tan(fov_h / 2.0) / aspect)
        self.projection = _perspective(self.fov_v, aspect, self.near, self.far)
        fx = 0.5 * self.width / math.tan(fov_h / 2.0)
        fy = 0.5 * self.height / math.tan(self.fov_v / 2.0)
        self.intrinsics = np.array([[fx, 0.0, 0.5 * self.width], [0.0, fy, 0.5 * self.height], [0.0, 0.0, 1.0]])

    def capture(self, world, time_s):
        origin, rot = _sensor_world_pose(_ego_frame(world), self.actual)
        view = _look_at(origin, rot)
        rgb, zbuf, ids = world.render(self.width, self.height, view, self.projection,
                                      segmentation=self.settings["segmentation"] == "on")
        # Non-linear z-buffer → metric depth along the optical axis [m].
        n, f = self.near, self.far
        depth = (f * n / (f - (f - n) * zbuf)).astype(np.float32)
        return Frame(self.name, time_s, {"image": rgb, "depth": depth, "segmentation": ids,
                                         "intrinsics": self.intrinsics})


@SENSORS.implements
class CameraRig(S.CameraRig, Sensor):
    """`cameras` pinhole cameras at one mount, evenly spread in yaw (camera k looks
    `yaw + k * 360 deg / cameras`), rendered each frame like `camera`. The rig's
    extrinsics are the mount's; camera k's are those turned by its yaw offset."""


    def __init__(self, name, settings):
        super().__init__(name, settings)
        n = int(self.settings["cameras"])
        self.yaw_offsets = tuple(2.0 * math.pi * k / n for k in range(n))
        self.cameras = [Camera(f"{name}.{k}", {**self.settings, "segmentation": "off"}) for k in range(n)]
        self.intrinsics = self.cameras[0].intrinsics
        self.width, self.height = self.cameras[0].width, self.cameras[0].height

    def camera_extrinsics(self, ext: Extrinsics) -> list[Extrinsics]:
        """Each camera's extrinsics for rig extrinsics `ext` (nominal or actual)."""
        return [ext.shifted(yaw=dy) for dy in self.yaw_offsets]

    def capture(self, world, time_s):
        images = np.empty((len(self.cameras), self.height, self.width, 3), dtype=np.uint8)
        for k, (cam, ext) in enumerate(zip(self.cameras, self.camera_extrinsics(self.actual))):
            cam.actual = ext
            images[k] = cam.capture(world, time_s).data["image"]
        return Frame(self.name, time_s, {"images": images, "intrinsics": self.intrinsics})


def _perspective(fov_v: float, aspect: float, near: float, far: float) -> list[float]:
    """OpenGL projection matrix, column-major (as pybullet's computeProjectionMatrixFOV)."""
    f = 1.0 / math.tan(fov_v / 2.0)
    return [f / aspect, 0.0, 0.0, 0.0,
            0.0, f, 0.0, 0.0,
            0.0, 0.0, (far + near) / (near - far), -1.0,
            0.0, 0.0, 2.0 * far * near / (near - far), 0.0]


def _look_at(origin: np.ndarray, rot: np.ndarray) -> list[float]:
    """OpenGL view matrix (column-major) of a camera at `origin` looking along its x axis."""
    forward, left, up = rot[:, 0], rot[:, 1], rot[:, 2]
    right = -left
    # Rows of the view rotation: camera x = right, y = up, z = -forward.
    m = np.array([right, up, -forward])
    t = matmul(-m, origin)
    return [m[0, 0], m[1, 0], m[2, 0], 0.0,
            m[0, 1], m[1, 1], m[2, 1], 0.0,
            m[0, 2], m[1, 2], m[2, 2], 0.0,
            t[0], t[1], t[2], 1.0]


def rotation(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """The 3x3 rotation Rz(yaw) Ry(pitch) Rx(roll) [rad] (`_rotation_into`)."""
    out = np.empty((3, 3))
    _rotation_into(roll, pitch, yaw, out)
    return out


@kernel
def _rotation_into(roll, pitch, yaw, out):
    """`rotation` into `out` (a 3x3 array), for kernels too."""
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch),
                              math.cos(yaw), math.sin(yaw))
    out[0, 0], out[0, 1], out[0, 2] = cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr
    out[1, 0], out[1, 1], out[1, 2] = sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr
    out[2, 0], out[2, 1], out[2, 2] = -sp, cp * sr, cp * cr


def _ego_frame(world) -> tuple[float, float, float, float, float]:
    """(x, y, z, heading, pitch) of the vehicle frame; flat ground for worlds without height."""
    frame = getattr(world, "ego_frame", None)
    if frame is not None:
        return frame()
    x, y, heading, _ = world.ego_pose()
    return x, y, 0.0, heading, 0.0


def _sensor_world_pose(vehicle_frame, ext: Extrinsics):
    """World position and rotation (columns: sensor x, y, z axes) of a sensor mount."""
    x, y, z, heading, pitch = vehicle_frame
    # Vehicle pitch is nose-up positive (road grade); a rotation about the left-pointing
    # y axis is nose-down positive, as for mount pitch (a positive mount pitch looks down).
    return _mount_pose(np.array([x, y, z]), rotation(0.0, -pitch, heading), np.array([ext.x, ext.y, ext.z]),
                       rotation(ext.roll, ext.pitch, ext.yaw))


@kernel
def _mount_pose(base, rot_v, mount, rot_m):
    """(base + rot_v mount, rot_v rot_m): a mount's world position [m] and rotation, by
    `kernel.matmul` (its bits, one call instead of two of its ~7 us wrapper)."""
    arm = np.empty((3, 1))
    matmul_into(rot_v, mount.reshape(3, 1), arm)
    origin = np.empty(3)
    for c in range(3):
        origin[c] = base[c] + arm[c, 0]
    rot = np.empty((3, 3))
    matmul_into(rot_v, rot_m, rot)
    return origin, rot


def sensor_to_vehicle(points: np.ndarray, ext: Extrinsics) -> np.ndarray:
    """Map sensor-frame points into the vehicle frame with extrinsics `ext`."""
    rot = rotation(ext.roll, ext.pitch, ext.yaw)
    return matmul(points, rot.T) + np.array([ext.x, ext.y, ext.z])
