"""Reference OSI stack: the bundled `bev` stack behind ASAM OSI, for `stack external protocol osi`.

    python -m addt_dsl.stack.osi_server [--address 127.0.0.1:5556] [--token T]
        [--max-message-bytes N] [--idle-timeout S] [--max-connections N]

Prints `listening HOST:PORT` once it accepts connections. Loopback unless told otherwise
(with a warning), a token if given, each message whole within the idle timeout and under
the size limit (checked before it is read); anything malformed gets an ERROR and the
connection is closed. Framing: `addt_dsl.stack.osi_transport`.

Each connection is one run. HELLO builds a `BevStack` (ground-truth perception) with the
settings and map it carries. Each SensorView whose timestamp is new is one perception
frame (its moving and stationary objects, each as if seen by two lidar returns; its
traffic lights as the stop lines ahead); every SensorView ticks the stack at the host's
time (`host_vehicle_data`), and the command due then (the stack's node latencies
included) is answered:

- MotionRequest: a desired state 0.5 s ahead, where a kinematic bicycle under that
  steering and acceleration from the host's pose gets to; the twin's follower
  (`osi_mapping.follow`) turns it back into the same command;
- TrafficUpdate: the host one step later, from this server's own copy of the twin's
  vehicle dynamics (`runtime.vehicle`) driven by the command.
"""

from __future__ import annotations

import hmac
import math
import socket
import sys
import time

import numpy as np

from addt_dsl.stack import osi_mapping as M
from addt_dsl.stack import osi_transport as T
from addt_dsl.stack.bridge import ProtocolError, escape
from addt_dsl.runtime.lights import StopStation
from addt_dsl.runtime.signs import junction_rule, next_sign
from addt_dsl.stack.bridge_server import (MAX_CONNECTIONS, BridgeServer, Limits, check_settings, RemoteFrame,
                                          RemoteActor, RemoteContext, run_server_cli)

from osi3.osi_motionrequest_pb2 import MotionRequest
from osi3.osi_sensorview_pb2 import SensorView
from osi3.osi_trafficlight_pb2 import TrafficLight
from osi3.osi_trafficupdate_pb2 import TrafficUpdate

DEFAULT_ADDRESS = "127.0.0.1:5556"
HORIZON_S = 0.5  # how far ahead a MotionRequest's desired state lies
IDLE_TIMEOUT_S = 60.0
MAX_MESSAGE_BYTES = T.MAX_MESSAGE_BYTES
_STATE_OF_COLOUR = {TrafficLight.Classification.COLOR_RED: 2.0, TrafficLight.Classification.COLOR_YELLOW: 1.0,
                    TrafficLight.Classification.COLOR_GREEN: 0.0}


class _OsiContext(RemoteContext):
    """The bridge server's context; the traffic lights come from the SensorViews."""

    def __init__(self, hello: dict):
        super().__init__(hello)
        self.lights: list[tuple[float, float]] = []  # (station on the road [m], state code), by station
        self.signs: list[float] = []  # stations of the stop signs' lines [m], by station
        self.rules: list[StopStation] = []  # every sign's line: station [m], `controller` its kind

    def stop_line_ahead(self, s: float):
        front = s + 0.5 * self.ego_length_m
        for u, state in self.lights:
            if u >= front - 0.5:
                return u, state
        return None

    def stop_sign_ahead(self, s: float, stopped: tuple[float, ...] = ()) -> float | None:
        return next_sign(self.signs, s + 0.5 * self.ego_length_m, stopped)

    def junction_rule(self, s: float) -> str | None:
        return junction_rule(self.rules, self.junctions, s + 0.5 * self.ego_length_m)


def rollout(pose: tuple[float, float, float, float], steer: float, accel: float, wheelbase_m: float,
            horizon_s: float = HORIZON_S) -> tuple[float, float, float, float, float]:
    """(x, y, yaw, speed, accel) a kinematic bicycle reaches after `horizon_s` under a
    constant (steer, accel) from (x, y, heading, speed); braking stops at speed 0."""
    x, y, heading, v = pose
    k = math.tan(steer) / wheelbase_m
    v_end = v + accel * horizon_s
    arc = v * horizon_s + 0.5 * accel * horizon_s ** 2
    if v_end < 0.0:
        v_end, arc = 0.0, v * v / (2.0 * -accel) if accel < 0 else 0.0
    turn = k * arc
    if abs(k) > 1e-12:
        ahead, left = math.sin(turn) / k, (1.0 - math.cos(turn)) / k
    else:
        ahead, left = arc, 0.0
    c, s = math.cos(heading), math.sin(heading)
    return x + c * ahead - s * left, y + s * ahead + c * left, heading + turn, v_end, accel


def motion_request(time_s: float, pose, steer: float, accel: float, wheelbase_m: float) -> MotionRequest:
    x, y, yaw, v, a = rollout(pose, steer, accel, wheelbase_m)
    mr = MotionRequest()
    M.set_version(mr.version)
    M.set_timestamp(mr.timestamp, time_s)
    mr.motion_request_type = MotionRequest.MOTION_REQUEST_TYPE_DESIRED_STATE
    d = mr.desired_state
    M.set_timestamp(d.timestamp, time_s + HORIZON_S)
    d.position.x, d.position.y, d.orientation.yaw = x, y, yaw
    c, s = math.cos(yaw), math.sin(yaw)
    d.velocity.x, d.velocity.y = v * c, v * s
    d.acceleration.x, d.acceleration.y = a * c, a * s
    return mr


def traffic_update(time_s: float, state, host_id: int) -> TrafficUpdate:
    """The host's state (a runtime.vehicle.VehicleState) at `time_s`, in the global frame."""
    tu = TrafficUpdate()
    M.set_version(tu.version)
    M.set_timestamp(tu.timestamp, time_s)
    u = tu.update.add()
    u.id.value = host_id
    c, s = math.cos(state.heading), math.sin(state.heading)
    b = u.base
    b.position.x, b.position.y, b.orientation.yaw = state.x, state.y, state.heading
    b.velocity.x, b.velocity.y = c * state.vx - s * state.vy, s * state.vx + c * state.vy
    b.acceleration.x, b.acceleration.y = c * state.accel - s * state.ay, s * state.accel + c * state.ay
    b.orientation_rate.yaw = state.yaw_rate
    return tu


def _check_hello(hello: dict, limits: Limits) -> None:
    from addt_dsl.stack.bev import BevStack

    if limits.token is not None and not hmac.compare_digest(str(hello.get("token", "")).encode(),
                                                            limits.token.encode()):
        raise PermissionError("wrong or missing token")
    if hello.get("protocol") != T.PROTOCOL_NAME or hello.get("version") != T.VERSION:
        raise ValueError(f"protocol {escape(str(hello.get('protocol')), 40)} version "
                         f"{escape(str(hello.get('version')), 20)} not supported "
                         f"(this server speaks {T.PROTOCOL_NAME} {T.VERSION})")
    if hello.get("answer") not in T.ANSWERS:
        raise ValueError(f"'answer' must be one of {', '.join(T.ANSWERS)}")
    check_settings(hello.get("stack"), BevStack.params, "stack")
    step = hello.get("step_s")
    if isinstance(step, bool) or not isinstance(step, (int, float)) or not 0.0 < step <= 1.0:
        raise ValueError("'step_s' must be a number in (0, 1] s")
    if not isinstance(hello.get("seed"), int) or not isinstance(hello.get("host_id"), int):
        raise ValueError("'seed' and 'host_id' must be integers")
    if not isinstance(hello.get("sensors"), list) or not any(
            isinstance(d, dict) and d.get("kind") == "lidar" for d in hello["sensors"]):
        raise ValueError("'sensors' must name the ego's lidar")


class _Session:
    """One run: the stack, its context, and (TrafficUpdate) the host's dynamics."""

    def __init__(self, hello: dict):
        from addt_dsl.runtime.vehicle import VehicleParams
        from addt_dsl.stack.bev import BevStack

        self.ctx = ctx = _OsiContext(hello)
        self.stack = BevStack(hello["stack"], ctx)
        ctx.faults.bind(self.stack, lambda: ctx.now)
        self.answer = T.ANSWERS[hello["answer"]]
        self.host_id = int(hello["host_id"])
        self.dt = float(hello["step_s"])
        self.lidar = next(d["name"] for d in hello["sensors"] if d.get("kind") == "lidar")
        # The stack's sensor as the views report objects: already where the stack should see them.
        sensor = ctx.sensors[self.lidar]
        sensor.nominal = sensor.actual = _Origin()
        e = hello["ego"]
        self.params = VehicleParams.for_vehicle(float(e["mass_kg"]), float(e["wheelbase_m"]), float(e["mu"]))
        self.vehicle = None
        self.queue: list = []
        self.command = (0.0, 0.0)
        self.last_view = None

    def on_view(self, sv: SensorView) -> bytes:
        ctx = self.ctx
        loc = sv.host_vehicle_data.location
        now = M.seconds(sv.host_vehicle_data.timestamp)
        x, y, yaw = loc.position.x, loc.position.y, loc.orientation.yaw
        speed = math.hypot(loc.velocity.x, loc.velocity.y)
        if not all(math.isfinite(v) for v in (now, x, y, yaw, speed)):
            raise ValueError("the host's state is not finite")
        ctx.now = now
        ctx.ego = (x, y, yaw, speed)
        ctx.ego_s = float(ctx.road.project(x, y, ctx.ego_s)[0])
        stamp = M.seconds(sv.timestamp)
        # A new stamp is a perception frame; a view sent again, or one without a stamp (no frame
        # yet: the host alone), is not.
        if sv.HasField("timestamp") and stamp != self.last_view:
            self.last_view = stamp
            self._frame(sv.global_ground_truth, stamp, now)
        self.stack.step(now, self.dt)
        ctx.commands.sort(key=lambda c: c[0])
        while ctx.commands and ctx.commands[0][0] <= now + 1e-12:  # due commands, as the twin's loop
            _, steer, accel = ctx.commands.pop(0)
            self.command = (steer, accel)
        steer, accel = self.command
        if self.answer == T.MOTION_REQUEST:
            return motion_request(now, ctx.ego, steer, accel, ctx.wheelbase_m).SerializeToString()
        from addt_dsl.runtime.vehicle import VehicleState, step

        if self.vehicle is None:
            self.vehicle = VehicleState(x, y, yaw, speed)
        step(self.vehicle, self.params, steer, accel, self.dt, 0.0)
        return traffic_update(now + self.dt, self.vehicle, self.host_id).SerializeToString()

    def _frame(self, gt, stamp: float, now: float) -> None:
        ctx = self.ctx
        actors = {}
        host = ctx.ego  # the host where the view's ground truth has it (at the view's time), else now
        for o in gt.moving_object:
            if o.id.value == self.host_id:
                b = o.base
                host = (b.position.x, b.position.y, b.orientation.yaw, math.hypot(b.velocity.x, b.velocity.y))
                continue
            b = o.base
            actors[o.id.value] = RemoteActor({"x": b.position.x, "y": b.position.y, "heading": b.orientation.yaw,
                                      "speed": math.hypot(b.velocity.x, b.velocity.y), "length_m": b.dimension.length,
                                      "width_m": b.dimension.width, "kind": M.object_kind(o)})
        for o in gt.stationary_object:
            b = o.base
            actors[o.id.value] = RemoteActor({"x": b.position.x, "y": b.position.y, "heading": b.orientation.yaw,
                                      "speed": 0.0, "length_m": b.dimension.length, "width_m": b.dimension.width,
                                      "kind": "obstacle"})
        for a in actors.values():
            if not all(math.isfinite(v) for v in (a.x, a.y, a.heading, a.speed, a.length_m, a.width_m)):
                raise ValueError("an object's state is not finite")
        lights = {}
        for tl in gt.traffic_light:
            if tl.classification.mode == TrafficLight.Classification.MODE_OFF:
                continue
            p = tl.base.position
            u = float(ctx.road.project(p.x, p.y, ctx.ego_s)[0])
            lights[tl.id.value // 10] = (u, _STATE_OF_COLOUR.get(tl.classification.color, 2.0))
        ctx.lights = sorted(lights.values())
        ctx.rules = sorted((StopStation(float(ctx.road.project(x, y, ctx.ego_s)[0]), kind)
                            for kind, x, y in M.sign_positions(gt)), key=lambda st: (st.u, st.controller))
        ctx.signs = [st.u for st in ctx.rules if st.controller == "stop"]
        hits = np.repeat(np.array(sorted(actors), dtype=np.int64), 2)  # two returns each: seen
        self.stack.on_frame(RemoteFrame(self.lidar, stamp, {"hit_body": hits}, host, actors), now)


class _Origin:
    x = y = z = roll = pitch = yaw = 0.0


def serve_connection(sock: socket.socket, limits: Limits = Limits(max_message_bytes=MAX_MESSAGE_BYTES,
                                                                  idle_timeout_s=IDLE_TIMEOUT_S)) -> None:
    """One OSI session until BYE, the peer closes, a deadline passes or a message is
    malformed (answered with ERROR, then closed)."""
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    session = None
    try:
        while True:
            deadline = time.monotonic() + limits.idle_timeout_s
            try:
                kind, payload = T.recv_message(sock, limits.max_message_bytes, deadline)
            except (ConnectionError, TimeoutError):
                return
            except (ProtocolError, OSError) as exc:
                reply_error(sock, str(exc), deadline)
                return
            try:
                if kind == T.HELLO:
                    if session is not None:
                        raise ValueError("a second hello on one connection")
                    hello = T.parse_json(payload, kind)
                    _check_hello(hello, limits)
                    session = _Session(hello)
                    T.send_json(sock, T.READY, {"version": T.VERSION, "stack": "bev"}, deadline)
                elif kind == T.SENSOR_VIEW:
                    if session is None:
                        raise ValueError("SensorView before hello")
                    reply = session.on_view(T.parse_proto(payload, SensorView))
                    T.send_message(sock, session.answer, reply, deadline)
                elif kind == T.BYE:
                    return
                else:
                    raise ValueError(f"unexpected {T.TYPE_NAMES[kind]}")
            except Exception as exc:  # noqa: BLE001 - reported to the simulator, which marks the run
                reply_error(sock, f"{type(exc).__name__}: {exc}", deadline)
                return
    finally:
        if session is not None:
            session.ctx.faults.close()


def reply_error(sock: socket.socket, message: str, deadline: float) -> None:
    try:
        T.send_json(sock, T.ERROR, {"message": escape(message)}, max(deadline, time.monotonic() + 1.0))
    except OSError:
        pass


def start_in_thread(address: str = "127.0.0.1:0", limits: Limits | None = None,
                    max_connections: int = MAX_CONNECTIONS) -> BridgeServer:
    """A server on a background thread (tests, notebooks); `shutdown()` it when done."""
    import threading

    server = BridgeServer(address, limits or Limits(None, MAX_MESSAGE_BYTES, IDLE_TIMEOUT_S), max_connections,
                          serve_connection, reply_error)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server


def main(argv=None) -> int:
    return run_server_cli(argv, "python -m addt_dsl.stack.osi_server", __doc__.split("\n")[0], DEFAULT_ADDRESS,
                          serve_connection, reply_error, MAX_MESSAGE_BYTES, IDLE_TIMEOUT_S)

if __name__ == "__main__":
    sys.exit(main())
