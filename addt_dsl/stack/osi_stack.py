"""`stack external protocol osi`: a stack behind ASAM OSI, lock-step over TCP (docs/bridge.md).

Each physics step the twin sends one `osi3.SensorView` and waits for the answer the
scenario declared: a MotionRequest (a desired state or trajectory, which the follower in
`osi_mapping.follow` turns into steering and acceleration commands that the twin's
dynamics execute, actuator lag and friction included) or a TrafficUpdate (the host's new
state, which the twin takes in place of its dynamics step: `move_host`).

The SensorView is built on the ego's lidar frames as they reach the stack, so sensor
faults act on what is sent: the ground truth is the world at the frame's stamp (a delayed
or skewed frame sends an older world), the objects are those the frame saw (at least
`MIN_HITS` returns, as `stack bev`'s ground-truth perception: noise dropout and occlusion
hide objects), a shifted mount misplaces them as it misplaces detections; when no frame
arrives (a drop), the previous view is sent again with its own stamp. The host's own
state now travels in `host_vehicle_data`.
"""

from __future__ import annotations

import json
import math
import os
import socket
import time
from collections import deque

import numpy as np

from addt_dsl.kernel import matmul
from addt_dsl.stack import osi_mapping as M
from addt_dsl.stack import osi_transport as T
from addt_dsl.stack.bev import StackError
from addt_dsl.stack.bridge import (CLIENT_SETTINGS, TOKEN_ENV, ExternalStack, ProtocolError, jsonable,
                                   check_address, escape, extrinsics_dict, parse_address)
from addt_dsl.stack.nodes import hit_counts

from osi3.osi_motionrequest_pb2 import MotionRequest
from osi3.osi_sensorview_pb2 import SensorView
from osi3.osi_trafficupdate_pb2 import TrafficUpdate

MIN_HITS = 2  # lidar returns that make an object seen (GroundTruthPerception's default)
HISTORY_S = 10.0  # ground truth kept for delayed and skewed frames [s]
MAX_UPDATE_AGE_S = 1.0  # a TrafficUpdate's timestamp this far from the step it moves the host to is refused


class OsiStack(ExternalStack):
    """The `osi` protocol's client: `ExternalStack`'s settings, OSI messages on the wire."""

    def __init__(self, settings: dict, ctx):
        super().__init__(settings, ctx)
        self.answer = str(self.settings["answer"])
        self._history: deque = deque()  # (time_s, {name: ObjectState}, [LightState]) per step
        self._view: M.WorldView | None = None
        self._sensed = False  # a lidar frame has made a view
        self._view_sensor = None
        self._static: bytes = b""  # the lanes, as SensorView bytes (protobuf merges concatenated messages)
        self._targets: list[M.Target] | None = None
        self._host: M.HostState | None = None
        self._ids = {"ego": M.HOST_ID, **{name: M.HOST_ID + 1 + k for k, name in enumerate(ctx.agent_names())}}
        if self.answer == "traffic_update":
            self.move_host = self._move_host

    # ---- connection
    def _connect(self) -> None:
        if self.internal_faults:
            # The compiler refuses this (E0109); a RunSpec built by hand ends here, detected.
            raise StackError(f"`stack external protocol osi` cannot apply {self._faults_text()}")
        host, port = parse_address(str(self.settings["address"]))
        check_address(host)
        self._static = _lanes_bytes(self.ctx.ego_route_roads())
        signs = self.ctx.ego_signs()
        if signs:  # static too: sent with every view, as the lanes
            sv = SensorView()
            sv.global_ground_truth.CopyFrom(M.signs_ground_truth(signs))
            self._static += sv.SerializeToString()
        try:
            self.sock = socket.create_connection((host, port), timeout=float(self.settings["timeout"]))
        except OSError as exc:
            raise StackError(f"cannot reach the OSI stack at {escape(host)}:{port}: {exc}") from None
        try:
            self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            kind, payload = self._exchange(T.HELLO, self._osi_hello(), T.READY)
            ready = T.parse_json(payload, kind)
            if ready.get("version") != T.VERSION:
                raise StackError(f"the OSI stack answered version {escape(repr(ready.get('version')), 40)}, "
                                 f"expected {T.VERSION}")
        except BaseException:
            self.sock.close()
            self.sock = None
            raise

    def _osi_hello(self) -> bytes:
        hello = self._hello()  # the bridge's: seed, step, ego body, sensors, map, remote settings
        hello.pop("protocol", None)
        hello.update(type="hello", protocol=T.PROTOCOL_NAME, version=T.VERSION,
                     osi_version=".".join(map(str, M.OSI_VERSION)), answer=self.answer, host_id=M.HOST_ID,
                     stack={k: v for k, v in hello["stack"].items() if k not in CLIENT_SETTINGS})
        token = os.environ.get(TOKEN_ENV)
        if token:
            hello["token"] = token
        return json.dumps(jsonable(hello), separators=(",", ":"), allow_nan=False).encode()

    def _exchange(self, kind: int, payload: bytes, expect: int) -> tuple[int, bytes]:
        """Send one message and read the reply, the whole exchange within `timeout`."""
        deadline = time.monotonic() + float(self.settings["timeout"])
        try:
            T.send_message(self.sock, kind, payload, deadline)
            got, reply = T.recv_message(self.sock, T.MAX_MESSAGE_BYTES, deadline)
        except (OSError, ConnectionError, ProtocolError) as exc:  # TimeoutError is an OSError
            raise StackError(f"OSI stack: {type(exc).__name__}: {escape(str(exc))}") from None
        if got == T.ERROR:
            message = T.parse_json(reply, got).get("message", "") if len(reply) <= T.MAX_JSON_BYTES else ""
            raise StackError(f"OSI stack error: {escape(str(message))}")
        if got != expect:
            raise StackError(f"OSI stack sent {T.TYPE_NAMES[got]}, expected {T.TYPE_NAMES[expect]}")
        return got, reply

    def close(self) -> None:
        if getattr(self, "sock", None) is None:
            return
        try:
            T.send_message(self.sock, T.BYE, b"", time.monotonic() + 1.0)
        except OSError:
            pass
        self.sock.close()
        self.sock = None

    # ---- the stack interface the loop drives
    def on_frame(self, frame, arrive_s: float) -> None:
        if "hit_body" in frame.data:  # lidar frames make views; other sensors' are not sent
            self._frames.append((frame, arrive_s))

    def step(self, time_s: float, dt: float):
        ctx = self.ctx
        ctx.now = time_s
        self._snapshot(time_s)
        if self._frames:
            frame, _ = self._frames[-1]  # the newest that arrived this step
            self._frames = []
            self._view = self._view_of(frame)
            self._sensed = True
        if self._view is None:  # before the first frame: the host alone, now
            self._view = M.WorldView(time_s, self._history[-1][1]["ego"], [], self._history[-1][2])
        if self.sock is None:
            self._connect()
        host_now = self._history[-1][1]["ego"]
        sv = M.sensor_view(self._view, host_now, time_s, sensed=self._sensed)
        self.objects_seen = len(self._view.objects)
        want = T.ANSWERS[self.answer]
        _, reply = self._exchange(T.SENSOR_VIEW, sv.SerializeToString() + self._static, want)
        try:
            if want == T.MOTION_REQUEST:
                self._targets = M.targets_from_motion_request(T.parse_proto(reply, MotionRequest))
            else:
                host = M.host_from_traffic_update(T.parse_proto(reply, TrafficUpdate), M.HOST_ID)
                if abs(host.time_s - (time_s + dt)) > MAX_UPDATE_AGE_S:
                    raise M.MappingError(f"TrafficUpdate stamped {host.time_s:.3f} s moves the host at "
                                         f"{time_s + dt:.3f} s")
                self._host = host
        except (ProtocolError, M.MappingError) as exc:
            raise StackError(f"OSI stack: {escape(str(exc))}") from None
        if want == T.TRAFFIC_UPDATE:
            return (0.0, 0.0)
        steer, accel = M.follow(self._targets, ctx.ego_pose(), time_s, float(ctx.wheelbase_m))
        if not (math.isfinite(steer) and math.isfinite(accel)):
            raise StackError("the motion request gives a non-finite command")
        ctx.apply_command_at(time_s, steer, accel)
        return steer, accel

    def _move_host(self, state, time_s: float) -> None:
        """The host where the last TrafficUpdate put it, carried on at its velocity,
        acceleration and yaw rate to `time_s` (the update's own instant: no change)."""
        h = self._host
        if h is None:
            return
        dt = time_s - h.time_s
        yaw = h.yaw + h.yaw_rate * dt
        vx, vy = h.vx + h.ax * dt, h.vy + h.ay * dt
        c, s = math.cos(yaw), math.sin(yaw)
        state.x = h.x + h.vx * dt + 0.5 * h.ax * dt * dt
        state.y = h.y + h.vy * dt + 0.5 * h.ay * dt * dt
        state.heading = yaw
        state.vx, state.vy = c * vx + s * vy, -s * vx + c * vy  # body frame
        state.yaw_rate = h.yaw_rate
        state.accel, state.ay = c * h.ax + s * h.ay, -s * h.ax + c * h.ay  # body frame

    # ---- the world as the views report it
    def _snapshot(self, time_s: float) -> None:
        ctx = self.ctx
        e, ego_z = ctx.ego_body()
        ego = ctx.ego_plan
        c, s = math.cos(e.heading), math.sin(e.heading)
        objects = {"ego": M.ObjectState(
            M.HOST_ID, "ego", e.x, e.y, ego_z + 0.5 * ego.height_m, e.heading, c * e.vx - s * e.vy,
            s * e.vx + c * e.vy, ego.length_m, ego.width_m, ego.height_m, c * e.accel - s * e.ay,
            s * e.accel + c * e.ay, e.yaw_rate, e.pitch)}
        for name, vehicle, gt, accel, height_m, z, grade in ctx.agent_truths():
            if gt is None:
                continue
            ch, sh = math.cos(gt.heading), math.sin(gt.heading)
            objects[name] = M.ObjectState(
                self._ids[name], vehicle, gt.x, gt.y, z + 0.5 * height_m, gt.heading,
                gt.speed * ch, gt.speed * sh, gt.length_m, gt.width_m, height_m, accel * ch, accel * sh,
                0.0, math.atan(grade))
        self._history.append((time_s, objects, _lights(ctx, time_s)))
        while self._history and self._history[0][0] < time_s - HISTORY_S:
            self._history.popleft()

    def _view_of(self, frame) -> M.WorldView:
        """The view a lidar frame gives: the world at its stamp, the objects it saw."""
        stamp = frame.stamp_s
        snap = self._history[0]
        for entry in self._history:  # the newest snapshot not after the stamp
            if entry[0] <= stamp + 1e-9:
                snap = entry
            else:
                break
        _, objects, lights = snap
        ids, counts = hit_counts(frame.data["hit_body"])
        seen = {self.ctx.body_name(int(b)) for b, n in zip(ids, counts) if n >= MIN_HITS}
        sensor = self.ctx.sensor(frame.sensor)
        host = objects["ego"]
        out = [_as_mounted(objects[name], host, sensor) for name in objects
               if name != "ego" and name in seen]
        return M.WorldView(stamp, host, out, lights)


def _as_mounted(o: M.ObjectState, host: M.ObjectState, sensor) -> M.ObjectState:
    """An object where a stack that trusts the calibrated mount places it when the mount
    has moved (`shift`): seen through the actual mount, mapped back through the nominal one
    (the formula of `nodes.GroundTruthPerception`); unchanged when the two agree."""
    actual, nominal = sensor.actual, sensor.nominal
    if extrinsics_dict(actual) == extrinsics_dict(nominal):
        return o
    from dataclasses import replace

    from addt_dsl.runtime.sensors import rotation

    c, s = math.cos(host.yaw), math.sin(host.yaw)
    dx, dy = o.x - host.x, o.y - host.y
    pv = np.array([c * dx + s * dy, -s * dx + c * dy, 0.8])
    ps = matmul(rotation(actual.roll, actual.pitch, actual.yaw).T, pv - np.array([actual.x, actual.y, actual.z]))
    pn = matmul(rotation(nominal.roll, nominal.pitch, nominal.yaw), ps) + np.array([nominal.x, nominal.y, nominal.z])
    return replace(o, x=host.x + c * float(pn[0]) - s * float(pn[1]), y=host.y + s * float(pn[0]) + c * float(pn[1]),
                   yaw=o.yaw - (actual.yaw - nominal.yaw))


def _lights(ctx, time_s: float) -> list[M.LightState]:
    """Each stop line on the ego's road or route, at the ego lane's centre, with its state."""
    return [M.LightState(k, controller, x, y, z, h + math.pi, ctx.light_state(controller, time_s))
            for k, (controller, x, y, z, h) in enumerate(ctx.ego_stop_lines())]


def _lanes_bytes(roads) -> bytes:
    """The roads' lanes, once per run, as a SensorView's bytes (appended to each view's):
    those of the ego's road or route (a whole imported map would make every view megabytes)."""
    from addt_dsl.runtime.roadmesh import Elevation

    elevations = [Elevation(r) for r in roads]
    lanes, boundaries = M.sample_lanes(roads, lambda i, s: elevations[i].at(s)[0])
    sv = SensorView()
    sv.global_ground_truth.CopyFrom(M.lanes_ground_truth(lanes, boundaries))
    return sv.SerializeToString()
