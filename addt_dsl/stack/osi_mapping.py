"""The twin's world <-> ASAM OSI messages (osi3, the `osi` extra): no sockets here.

The transport (`osi_transport`, TCP lock-step) and the trace writer (`addtc trace --osi`)
both use this module, so another transport (ROS 2, ZeroMQ) can reuse the mapping.

Frames and units (docs/bridge.md#the-osi-mapping): OSI's global frame is the twin's map
frame (right-handed, x east, y north, z up, metres); an object's `base.position` is the
centre of its bounding box (the twin's box centre, `z` = road height + half the body
height); `orientation.yaw` is the heading counter-clockwise from +x [rad]; `pitch` is
OSI's (right-handed about y, so a nose-up grade is negative); velocities and
accelerations are in the global frame [m/s, m/s^2]. Timestamps are seconds + nanoseconds
of simulated time.

Inputs are plain dataclasses (`ObjectState`, `LightState`, `LaneGeometry`,
`BoundaryGeometry`, `WorldView`) so the mapping is tested with hand-made values.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from addt_dsl.plan import LIGHT_STATES
from addt_dsl.runtime.signs import SIGN_KINDS

from osi3.osi_groundtruth_pb2 import GroundTruth
from osi3.osi_lane_pb2 import Lane, LaneBoundary
from osi3.osi_motionrequest_pb2 import MotionRequest
from osi3.osi_object_pb2 import MovingObject, StationaryObject
from osi3.osi_sensorview_pb2 import SensorView
from osi3.osi_trafficlight_pb2 import TrafficLight
from osi3.osi_trafficsign_pb2 import TrafficSign
from osi3.osi_trafficupdate_pb2 import TrafficUpdate
from osi3 import osi_version_pb2

_OSI_INTERFACE = osi_version_pb2.DESCRIPTOR.GetOptions().Extensions[osi_version_pb2.current_interface_version]
OSI_VERSION = tuple(getattr(_OSI_INTERFACE, k) for k in ("version_major", "version_minor", "version_patch"))

HOST_ID = 1  # the ego's OSI id; agents follow in plan order (2, 3, ...)
LIGHT_ID_BASE = 1_000_000  # traffic-light bulbs: base + 10 * signal index + bulb (0 red, 1 yellow, 2 green)
LANE_ID_BASE = 2_000_000  # lanes and lane boundaries (`lane_id`, `boundary_id`)
SIGN_ID_BASE = 3_000_000  # stop signs: base + index along the ego's route

# The vehicle catalogue's kinds (addt_dsl.vehicles) as OSI classifications.
_MOVING_TYPE = {
    "car": (MovingObject.TYPE_VEHICLE, MovingObject.VehicleClassification.TYPE_MEDIUM_CAR),
    "ego": (MovingObject.TYPE_VEHICLE, MovingObject.VehicleClassification.TYPE_MEDIUM_CAR),
    "truck": (MovingObject.TYPE_VEHICLE, MovingObject.VehicleClassification.TYPE_HEAVY_TRUCK),
    "cyclist": (MovingObject.TYPE_VEHICLE, MovingObject.VehicleClassification.TYPE_BICYCLE),
    "pedestrian": (MovingObject.TYPE_PEDESTRIAN, None),
}
STATIONARY_KINDS = {"obstacle": StationaryObject.Classification.TYPE_OTHER}
# And back (what a remote stack's objects are to the twin's planner), first match wins.
_KIND_OF_VEHICLE = {MovingObject.VehicleClassification.TYPE_HEAVY_TRUCK: "truck",
                    MovingObject.VehicleClassification.TYPE_BICYCLE: "cyclist"}
_BULBS = (("red", TrafficLight.Classification.COLOR_RED), ("yellow", TrafficLight.Classification.COLOR_YELLOW),
          ("green", TrafficLight.Classification.COLOR_GREEN))


class MappingError(ValueError):
    """An OSI message from the peer that the twin cannot apply (missing or non-finite fields)."""


@dataclass(frozen=True)
class ObjectState:
    """One actor at one instant, in the map frame (SI)."""

    id: int
    kind: str  # vehicles.VEHICLES key, or "ego"
    x: float  # bounding-box centre [m]
    y: float
    z: float
    yaw: float  # heading, counter-clockwise from +x [rad]
    vx: float  # velocity, global frame [m/s]
    vy: float
    length: float  # [m]
    width: float
    height: float
    ax: float = 0.0  # acceleration, global frame [m/s^2]
    ay: float = 0.0
    yaw_rate: float = 0.0  # [rad/s]
    pitch_nose_up: float = 0.0  # road grade angle under it [rad]


@dataclass(frozen=True)
class LightState:
    """One signal: where its stop line meets the ego's lane (the twin has no light heads)."""

    index: int
    name: str
    x: float
    y: float
    z: float
    yaw: float  # the direction traffic faces it from [rad]
    state: float  # LIGHT_STATES code


@dataclass(frozen=True)
class BoundaryGeometry:
    id: int
    points: tuple[tuple[float, float, float], ...]
    solid: bool


@dataclass(frozen=True)
class LaneGeometry:
    id: int
    centerline: tuple[tuple[float, float, float], ...]  # in the road's +s order
    driving: bool  # a driving lane (else OSI TYPE_NONDRIVING)
    along_s: bool  # traffic drives in the centreline's order
    left_boundary: int  # ids, left and right looking along the centreline
    right_boundary: int


@dataclass
class WorldView:
    """What one SensorView carries: the world at `time_s` as the view reports it."""

    time_s: float
    host: ObjectState
    objects: list[ObjectState] = field(default_factory=list)  # other actors (moving and stationary kinds)
    lights: list[LightState] = field(default_factory=list)


# ---------------------------------------------------------------- small pieces

def set_timestamp(msg, time_s: float) -> None:
    """OSI Timestamp from seconds: whole seconds and nanoseconds in [0, 1e9)."""
    total = int(round(time_s * 1e9))
    msg.seconds, msg.nanos = divmod(total, 1_000_000_000)


def seconds(msg) -> float:
    return msg.seconds + msg.nanos * 1e-9


def set_version(msg) -> None:
    msg.version_major, msg.version_minor, msg.version_patch = OSI_VERSION


def _fill_base(base, o: ObjectState, moving: bool = True) -> None:
    base.dimension.length, base.dimension.width, base.dimension.height = o.length, o.width, o.height
    base.position.x, base.position.y, base.position.z = o.x, o.y, o.z
    base.orientation.yaw = o.yaw
    base.orientation.pitch = -o.pitch_nose_up  # OSI pitch: right-handed about y (left), nose up < 0
    base.orientation.roll = 0.0
    if moving:
        base.velocity.x, base.velocity.y, base.velocity.z = o.vx, o.vy, 0.0
        base.acceleration.x, base.acceleration.y, base.acceleration.z = o.ax, o.ay, 0.0
        base.orientation_rate.yaw = o.yaw_rate


def fill_moving(msg: MovingObject, o: ObjectState) -> None:
    msg.id.value = o.id
    _fill_base(msg.base, o)
    kind, vehicle = _MOVING_TYPE.get(o.kind, (MovingObject.TYPE_UNKNOWN, None))
    msg.type = kind
    if vehicle is not None:
        msg.vehicle_classification.type = vehicle
        if o.id == HOST_ID:
            msg.vehicle_attributes.bbcenter_to_rear.x = 0.0  # the twin's reference point is the box centre


def fill_stationary(msg: StationaryObject, o: ObjectState) -> None:
    msg.id.value = o.id
    _fill_base(msg.base, o, moving=False)
    msg.classification.type = STATIONARY_KINDS.get(o.kind, StationaryObject.Classification.TYPE_OTHER)


def fill_light(gt: GroundTruth, light: LightState) -> None:
    """Three bulbs per signal (OSI: one TrafficLight per bulb), the lit one CONSTANT."""
    lit = next((n for n, code in LIGHT_STATES.items() if code == light.state), None)
    for k, (name, colour) in enumerate(_BULBS):
        tl = gt.traffic_light.add()
        tl.id.value = LIGHT_ID_BASE + 10 * light.index + k
        b = tl.base
        b.dimension.length, b.dimension.width, b.dimension.height = 0.3, 0.3, 0.3
        b.position.x, b.position.y, b.position.z = light.x, light.y, light.z
        b.orientation.yaw = light.yaw
        tl.classification.color = colour
        tl.classification.icon = TrafficLight.Classification.ICON_NONE
        tl.classification.mode = TrafficLight.Classification.MODE_CONSTANT if name == lit \
            else TrafficLight.Classification.MODE_OFF


def signs_ground_truth(signs: list[tuple[str, float, float, float, float]]) -> GroundTruth:
    """Signs as TrafficSigns (their kind's first OSI type, `signs.SIGN_KINDS`), each where its
    line meets the ego's lane, facing the traffic it holds: (kind, x, y, z, yaw of the ego's
    lane there) each."""
    gt = GroundTruth()
    for k, (kind, x, y, z, yaw) in enumerate(signs):
        ts = gt.traffic_sign.add()
        ts.id.value = SIGN_ID_BASE + k
        b = ts.main_sign.base
        b.dimension.length, b.dimension.width, b.dimension.height = 0.05, 0.9, 0.9
        b.position.x, b.position.y, b.position.z = x, y, z
        b.orientation.yaw = math.remainder(yaw + math.pi, 2.0 * math.pi)  # its face towards the traffic
        ts.main_sign.classification.type = TrafficSign.MainSign.Classification.Type.Value(
            SIGN_KINDS[kind].osi_types[0])
    return gt


_KIND_OF_OSI = {TrafficSign.MainSign.Classification.Type.Value(t): k.name
                for k in SIGN_KINDS.values() for t in k.osi_types}


def sign_positions(gt: GroundTruth) -> list[tuple[str, float, float]]:
    """(kind, x, y) of each sign of a `SIGN_KINDS` kind (by its main sign's type) in a
    GroundTruth, in message order."""
    return [(_KIND_OF_OSI[ts.main_sign.classification.type], ts.main_sign.base.position.x,
             ts.main_sign.base.position.y) for ts in gt.traffic_sign
            if ts.main_sign.classification.type in _KIND_OF_OSI]


def lanes_ground_truth(lanes: list[LaneGeometry], boundaries: list[BoundaryGeometry]) -> GroundTruth:
    """The static part of every GroundTruth (lanes and their boundaries)."""
    gt = GroundTruth()
    for b in boundaries:
        lb = gt.lane_boundary.add()
        lb.id.value = b.id
        lb.classification.type = LaneBoundary.Classification.TYPE_SOLID_LINE if b.solid \
            else LaneBoundary.Classification.TYPE_DASHED_LINE
        lb.classification.color = LaneBoundary.Classification.COLOR_WHITE
        for x, y, z in b.points:
            p = lb.boundary_line.add()
            p.position.x, p.position.y, p.position.z = x, y, z
    for lane in lanes:
        ln = gt.lane.add()
        ln.id.value = lane.id
        c = ln.classification
        c.type = Lane.Classification.TYPE_DRIVING if lane.driving else Lane.Classification.TYPE_NONDRIVING
        c.centerline_is_driving_direction = lane.along_s
        for x, y, z in lane.centerline:
            p = c.centerline.add()
            p.x, p.y, p.z = x, y, z
        c.left_lane_boundary_id.add().value = lane.left_boundary
        c.right_lane_boundary_id.add().value = lane.right_boundary
    return gt


def ground_truth(view: WorldView, static: GroundTruth | None = None, sensed: bool = True) -> GroundTruth:
    """The GroundTruth of a view: the host among the moving objects, the other actors
    (stationary kinds as StationaryObjects), the lights' bulbs, `static`'s lanes; stamped
    with the view's time where a frame made it (`sensed`)."""
    gt = GroundTruth()
    set_version(gt.version)
    if sensed:
        set_timestamp(gt.timestamp, view.time_s)
    gt.host_vehicle_id.value = view.host.id
    fill_moving(gt.moving_object.add(), view.host)
    for o in view.objects:
        if o.kind in STATIONARY_KINDS:
            fill_stationary(gt.stationary_object.add(), o)
        else:
            fill_moving(gt.moving_object.add(), o)
    for light in view.lights:
        fill_light(gt, light)
    if static is not None:
        gt.MergeFrom(static)
    return gt


def sensor_view(view: WorldView, host_now: ObjectState, now_s: float,
                static: GroundTruth | None = None, sensed: bool = True) -> SensorView:
    """A SensorView: `view`'s ground truth (stamped with the view's time, which a delayed,
    skewed or dropped frame makes older than now) and the host's own state now
    (`host_vehicle_data`, stamped `now_s`: the vehicle knows its odometry on time).
    Before the sensor's first frame (`sensed` false) the view has no `timestamp`: there is
    no frame to stamp, and a stamp would collide with the first frame's when that arrives late."""
    sv = SensorView()
    set_version(sv.version)
    if sensed:
        set_timestamp(sv.timestamp, view.time_s)
    sv.sensor_id.value = 0
    sv.host_vehicle_id.value = host_now.id
    sv.global_ground_truth.CopyFrom(ground_truth(view, static, sensed))
    hv = sv.host_vehicle_data
    set_version(hv.version)
    set_timestamp(hv.timestamp, now_s)
    hv.host_vehicle_id.value = host_now.id
    _fill_base(hv.location, host_now)
    return sv


# ---------------------------------------------------------------- from OSI

def _finite(*values: float, what: str) -> None:
    if not all(math.isfinite(v) for v in values):
        raise MappingError(f"{what} is not finite")


@dataclass(frozen=True)
class HostState:
    """The host's state a TrafficUpdate sets (map frame, SI)."""

    time_s: float
    x: float
    y: float
    yaw: float
    vx: float  # global frame [m/s]
    vy: float
    ax: float
    ay: float
    yaw_rate: float


def host_from_traffic_update(tu: TrafficUpdate, host_id: int = HOST_ID) -> HostState:
    """The host's new state from a TrafficUpdate: the `update` whose id is the host's,
    at the update's timestamp (its base's position is the box centre)."""
    if not tu.HasField("timestamp"):
        raise MappingError("TrafficUpdate has no timestamp")
    match = [u for u in tu.update if u.id.value == host_id]
    if len(match) != 1:
        raise MappingError(f"TrafficUpdate has {len(match)} updates for the host (id {host_id}), not one")
    b = match[0].base
    if not (b.HasField("position") and b.HasField("orientation") and b.HasField("velocity")):
        raise MappingError("the host's update lacks position, orientation or velocity")
    s = HostState(seconds(tu.timestamp), b.position.x, b.position.y, b.orientation.yaw, b.velocity.x, b.velocity.y,
                  b.acceleration.x, b.acceleration.y, b.orientation_rate.yaw)
    _finite(*(getattr(s, k) for k in HostState.__dataclass_fields__), what="the host's update")
    return s


@dataclass(frozen=True)
class Target:
    """Where a MotionRequest wants the host: time [s], position [m], yaw [rad], and the
    velocity [m/s] and acceleration [m/s^2] along the yaw when the request says them."""

    time_s: float
    x: float
    y: float
    yaw: float
    speed: float | None = None
    accel: float | None = None


def targets_from_motion_request(mr: MotionRequest) -> list[Target]:
    """A DesiredState as one target, a DesiredTrajectory as its points in time order."""
    if mr.motion_request_type == MotionRequest.MOTION_REQUEST_TYPE_DESIRED_STATE:
        d = mr.desired_state
        if not (d.HasField("timestamp") and d.HasField("position") and d.HasField("orientation")):
            raise MappingError("the desired state lacks timestamp, position or orientation")
        yaw = d.orientation.yaw
        c, s = math.cos(yaw), math.sin(yaw)
        speed = d.velocity.x * c + d.velocity.y * s if d.HasField("velocity") else None
        accel = d.acceleration.x * c + d.acceleration.y * s if d.HasField("acceleration") else None
        out = [Target(seconds(d.timestamp), d.position.x, d.position.y, yaw, speed, accel)]
    elif mr.motion_request_type == MotionRequest.MOTION_REQUEST_TYPE_TRAJECTORY:
        pts = mr.desired_trajectory.trajectory_point
        if not pts:
            raise MappingError("the desired trajectory has no points")
        out = sorted((Target(seconds(p.timestamp), p.position.x, p.position.y, p.orientation.yaw) for p in pts),
                     key=lambda t: t.time_s)
    else:
        raise MappingError(f"motion request type {int(mr.motion_request_type)} is neither a desired state "
                           "nor a desired trajectory")
    for t in out:
        _finite(t.time_s, t.x, t.y, t.yaw, *(v for v in (t.speed, t.accel) if v is not None),
                what="a motion request value")
    return out


# The follower: what the twin's actuators are asked for, so its dynamics (lag, friction,
# rate limits) execute a MotionRequest.
SPEED_GAIN = 0.5  # [1/s] speed error -> acceleration, on top of the request's own acceleration
MIN_LOOKAHEAD_S = 0.3  # a trajectory is pursued at least this far ahead in time


def _trajectory_target(targets: list[Target], now_s: float) -> Target:
    """The trajectory's point at `now_s` + lookahead (linear in time), with the speed and
    acceleration of its segments."""
    if len(targets) == 1:
        return targets[0]
    want = now_s + MIN_LOOKAHEAD_S
    k = 1
    while k < len(targets) - 1 and targets[k].time_s < want:
        k += 1
    a, b = targets[k - 1], targets[k]
    span = b.time_s - a.time_s
    if span <= 0:
        raise MappingError("trajectory points share a timestamp")
    u = min(max((want - a.time_s) / span, 0.0), 1.0)
    dyaw = math.remainder(b.yaw - a.yaw, math.tau)
    speed = math.hypot(b.x - a.x, b.y - a.y) / span
    accel = None
    if k + 1 < len(targets) and targets[k + 1].time_s > b.time_s:
        c = targets[k + 1]
        accel = (math.hypot(c.x - b.x, c.y - b.y) / (c.time_s - b.time_s) - speed) / (0.5 * (c.time_s - a.time_s))
    return Target(a.time_s + u * span, a.x + u * (b.x - a.x), a.y + u * (b.y - a.y), a.yaw + u * dyaw, speed, accel)


def follow(targets: list[Target], pose: tuple[float, float, float, float], now_s: float,
           wheelbase_m: float) -> tuple[float, float]:
    """(steer [rad], accel [m/s^2]) toward a MotionRequest's targets from the host's pose
    (x, y, heading [rad], speed [m/s]) now.

    Steering is pure pursuit to the target's position: the curvature 2 y / d^2 of the arc
    tangent to the heading through the target (y its lateral offset, d its distance), as a
    bicycle's steer atan(L k); a target closer than 0.05 m steers by the yaw error over one
    wheelbase. Acceleration is the request's own along its yaw plus `SPEED_GAIN` times the
    speed the target asks for minus the speed that acceleration reaches by then. A
    request from a kinematic bicycle rollout under (steer, accel) returns that command."""
    target = _trajectory_target(targets, now_s) if len(targets) > 1 else targets[0]
    x, y, heading, speed = pose
    dx, dy = target.x - x, target.y - y
    c, s = math.cos(heading), math.sin(heading)
    ahead, left = c * dx + s * dy, -s * dx + c * dy
    d2 = ahead * ahead + left * left
    if d2 > 0.05 ** 2:
        curvature = 2.0 * left / d2
    else:
        curvature = math.remainder(target.yaw - heading, math.tau) / wheelbase_m
    steer = math.atan(wheelbase_m * curvature)
    accel = target.accel if target.accel is not None else 0.0
    if target.speed is not None:
        dt = max(target.time_s - now_s, 0.0)
        accel += SPEED_GAIN * (target.speed - max(0.0, speed + accel * dt))  # braking stops, never reverses
    return steer, accel


def object_kind(msg: MovingObject) -> str:
    """The twin's vehicle kind of an OSI moving object (the planner's boxes and crossing rule)."""
    if msg.type == MovingObject.TYPE_PEDESTRIAN:
        return "pedestrian"
    return _KIND_OF_VEHICLE.get(msg.vehicle_classification.type, "car")


# ---------------------------------------------------------------- lanes from the road model

LANE_STEP_M = 5.0  # centre lines and boundaries sampled this far apart along the road


def sample_lanes(roads, elevation=None, step_m: float = LANE_STEP_M) -> tuple[list[LaneGeometry],
                                                                             list[BoundaryGeometry]]:
    """OSI lanes and boundaries of `roads` (addt_dsl.road.Road objects, in a fixed order):
    per lane section, each lane's centre line and its two borders sampled every `step_m`
    (and at the section's ends). Ids: `LANE_ID_BASE` + 10000 road + 100 section + 50 +
    lane id (a lane) or border index (a boundary: 0 the centre line, +-k the outer border
    of lane +-k). A border is solid at the road's edges and between the two directions,
    dashed between lanes of one direction. `elevation(road_index, s) -> z` [m] or None (0)."""
    import numpy as np

    from addt_dsl.road.lanes import DRIVING_TYPES

    lanes, boundaries = [], []
    for ri, road in enumerate(roads):
        for si, sec in enumerate(road.sections):
            s1 = min(sec.s1, float(road.length))
            n = max(2, int(math.ceil((s1 - sec.s0) / step_m)) + 1)
            s = np.linspace(sec.s0, s1, n)
            s[-1] = np.nextafter(s1, sec.s0) if si + 1 < len(road.sections) else s1  # stay in the section
            x, y, h = (np.asarray(v, dtype=float) for v in road.reference_pose(s))
            z = np.array([elevation(ri, float(v)) for v in s]) if elevation else np.zeros(n)
            ids = sec.lane_ids
            two_way = any(i > 0 for i in ids) and any(i < 0 for i in ids)
            base = LANE_ID_BASE + 10000 * ri + 100 * si + 50

            def points(t):
                return tuple((float(px), float(py), float(pz)) for px, py, pz in
                             zip(x - np.sin(h) * t, y + np.cos(h) * t, z) if math.isfinite(px))

            borders = {0: np.asarray(road.lane_border_t(0, s)[0], dtype=float)}
            for lane_id in ids:
                inner, outer = (np.asarray(v, dtype=float) for v in road.lane_border_t(lane_id, s))
                borders[lane_id] = outer
                along = road.travel_direction(lane_id) > 0
                inner_id = base + (0 if abs(lane_id) == 1 else lane_id - (1 if lane_id > 0 else -1))
                left, right = (inner_id, base + lane_id) if lane_id < 0 else (base + lane_id, inner_id)
                lanes.append(LaneGeometry(base + lane_id, points(0.5 * (inner + outer)),
                                          sec.lane(lane_id).type in DRIVING_TYPES, along, left, right))
            outermost = {min((i for i in ids if i < 0), default=0), max((i for i in ids if i > 0), default=0)}
            for k in sorted(borders):
                if k == 0 and not two_way and ids:
                    solid = True  # a one-way road's centre line is its edge
                else:
                    solid = k in outermost or k == 0
                boundaries.append(BoundaryGeometry(base + k, points(borders[k]), solid))
    return lanes, boundaries
