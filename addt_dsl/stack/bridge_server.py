"""Reference bridge server: hosts the default `bev` stack for `stack external` runs.

    python -m addt_dsl.stack.bridge_server [--address 127.0.0.1:5555] [--token T]
        [--max-message-bytes N] [--idle-timeout S] [--max-connections N]

Prints `listening HOST:PORT` once it accepts connections (`--address 127.0.0.1:0` picks a
free port). It binds loopback unless told otherwise, and warns when told otherwise. Each
message must arrive whole within the idle timeout and fit the size limit (checked before
it is read); anything malformed gets an `error` reply and the connection is closed.

Each connection is one run: `hello` builds a `BevStack` from the settings and the map it
carries (and, from protocol 2, a fault schedule from the stack-internal faults it carries,
bound to the stack as in process; in protocol 3, the stations of the stop lines and stop
signs on the ego's route), every `step` replays the step's frames (and, in protocol 3, the
lights' states) into it and ticks it, and replies with its commands and events (the
faults' injections among them), `bye` ends the run. Connections are served one thread each, so parallel runs may share a
server. It is also the worked example of the protocol in docs/bridge.md: a stack in any
language needs only to answer these three messages.
"""

from __future__ import annotations

import argparse
import hmac
import json
import math
import os
import re
import socket
import socketserver
import sys
import threading
import time
import zlib
from dataclasses import dataclass

import numpy as np

from addt_dsl.plan import LIGHT_STATES, ConcreteFault
from addt_dsl.registry import FAULTS
from addt_dsl.runtime.faults import FaultSchedule
from addt_dsl.runtime.lights import StopStation, next_stop
from addt_dsl.runtime.signs import SIGN_KINDS, junction_rule, next_sign
from addt_dsl.runtime.trace import SERIES_COLUMNS, Event
from addt_dsl.stack.bridge import (
    MAX_FAULTS,
    MAX_HEADER_BYTES,
    MAX_MESSAGE_BYTES,
    MAX_SIGNALS,
    PROTOCOLS,
    SIGNALS_PROTOCOL,
    TOKEN_ENV,
    ProtocolError,
    decode,
    escape,
    header_bytes,
    is_loopback,
    parse_address,
    recv_payload,
    send,
)

IDLE_TIMEOUT_S = 60.0  # wait for each whole message, from its first byte to its last
MAX_CONNECTIONS = 32  # runs served at once; more get an `error` reply


class _Extrinsics:
    def __init__(self, d: dict):
        self.x, self.y, self.z = d["x"], d["y"], d["z"]
        self.roll, self.pitch, self.yaw = d["roll"], d["pitch"], d["yaw"]


class _Sensor:
    def __init__(self, d: dict):
        self.name = d["name"]
        self.keyword = d["kind"]
        self.settings = d["settings"]
        self.nominal = _Extrinsics(d["nominal"])
        self.actual = self.nominal


class RemoteFrame:
    """A frame as a client sent it (`runtime.views.SensorFrame`)."""

    def __init__(self, sensor: str, stamp_s: float, data: dict, ego_pose: tuple, actors: dict | None = None):
        self.sensor, self.stamp_s, self.data = sensor, stamp_s, data
        self.ego_pose, self.actors = ego_pose, actors


class RemoteActor:
    def __init__(self, d: dict):
        self.x, self.y, self.heading, self.speed = d["x"], d["y"], d["heading"], d["speed"]
        self.length_m, self.width_m = d["length_m"], d["width_m"]
        self.kind = str(d.get("kind", ""))  # the actor's vehicle kind ("" from a client that sends none)


class RemoteContext:
    """What `BevStack` asks of the simulator (`runtime.views.StackContext`), answered from the
    bridge messages."""

    def __init__(self, hello: dict):
        from addt_dsl.plan import RoadPlan
        from addt_dsl.runtime.actor_road import ActorPath, ActorRoad, junction_legs
        from addt_dsl.road import resolve_route
        from addt_dsl.road.roadspec import build_network

        road_plan = RoadPlan.model_validate(hello["map"]["road"])
        network = build_network([road_plan])[road_plan.name]
        ego = hello["ego"]
        route = [str(r) for r in ego.get("route") or ()]
        road_id = route[0] if route else road_plan.xodr_road_id if road_plan.source == "xodr" and \
            road_plan.xodr_road_id else next(iter(network.roads))
        # The ego's road or route, as the simulator builds it (`state.RunState._road_of`): a client that
        # sends no route (an older one) gets its first road.
        lane = int(ego.get("map_lane", ego["lane"]))
        if not route and network.road(road_id).travel_direction(lane) > 0:
            path = ActorRoad(network, road_id, {})
        else:
            _, legs = resolve_route(network, route or [road_id], lane, float(ego.get("s_m", 0.0)))
            path = ActorPath(network, road_plan.name, legs, {})
        self.road, self.road_id = path.road, path.road_id
        self.junctions = junction_legs(path)
        self.seed = int(hello["seed"])
        self.wheelbase_m = float(hello["ego"]["wheelbase_m"])
        body = hello["ego"]
        self.ego_length_m, self.ego_width_m = float(body["length_m"]), float(body["width_m"])
        self.ego_mass_kg, self.ego_mu = float(body["mass_kg"]), float(body["mu"])
        self.ego_lane = int(hello["ego"]["lane"])
        self.sensors = {d["name"]: _Sensor(d) for d in hello["sensors"]}
        self.now = 0.0
        self.ego = (0.0, 0.0, 0.0, 0.0)
        self.ego_s = 0.0
        # Every event of the run, the stack's and the faults' in the order they happened
        # (as in process); each reply carries those since the last one.
        self.events: list[Event] = []
        self.sent = 0  # events sent so far
        self.series_sent: dict[int, int] = {}  # series fault event (position) -> entries sent
        # The stack-internal faults (protocol 2), applied by the same schedule as in process;
        # bound to the stack once it exists.
        faults = [ConcreteFault.model_validate(f) for f in hello.get("faults", [])]
        self.faults = FaultSchedule(faults, float(hello["step_s"]), float(hello.get("duration_s", math.inf)),
                                    self.events)
        self.commands: list = []
        # Protocol 3: the map's signals on the ego's route, as the in-process context reads
        # them (path order: by station, then controller), and each light's state this step.
        # An older client sends none: the stack then knows of no light and no sign.
        self.stop_lines = sorted((StopStation(float(d["station_m"]), str(d["controller"]))
                                  for d in hello.get("stop_lines", ())), key=lambda st: (st.u, st.controller))
        self.rules = sorted((StopStation(float(d["station_m"]), str(d["kind"])) for d in hello.get("signs", ())),
                            key=lambda st: (st.u, st.controller))
        self.sign_lines = [st.u for st in self.rules if st.controller == "stop"]
        self.light_states: dict[str, float] = {}

    # The same derivation as the in-process context, so a remote run matches a local one.
    def rng(self, name: str) -> np.random.Generator:
        return np.random.default_rng([self.seed, zlib.crc32(b"stack"), zlib.crc32(name.encode())])

    def ego_pose(self):
        return self.ego

    def ego_road(self):
        return self.road, self.road_id

    def sensor(self, name: str):
        return self.sensors[name]

    def stop_line_ahead(self, s: float):
        """As the simulator's context: (station, state code) of the next stop line ahead of
        the ego's front, from the hello's stop lines and this step's states; None without."""
        return next_stop(self.stop_lines, s + 0.5 * self.ego_length_m, self.light_states.__getitem__)

    def stop_sign_ahead(self, s: float, stopped: tuple[float, ...] = ()) -> float | None:
        """As the simulator's context: the next stop sign's line ahead but those in `stopped`."""
        return next_sign(self.sign_lines, s + 0.5 * self.ego_length_m, stopped)

    def junction_rule(self, s: float) -> str | None:
        """As the simulator's context: the rule of the ego's approach to the next junction."""
        return junction_rule(self.rules, self.junctions, s + 0.5 * self.ego_length_m)

    def junction_ahead(self, s: float):
        """As the simulator's context: the next junction on the route the ego's front has not left."""
        front = s + 0.5 * self.ego_length_m
        for entry, exit_, cx, cy in self.junctions:
            if exit_ > front:
                return entry, cx, cy, exit_
        return None

    def ego_station(self) -> float:
        return self.ego_s

    def event(self, kind: str, **detail) -> None:
        self.events.append(Event(self.now, kind, detail))

    def emit(self, event: Event) -> None:
        self.events.append(event)

    def apply_command_at(self, time_s: float, steer: float, accel: float) -> None:
        self.commands.append([time_s, steer, accel])


@dataclass(frozen=True)
class Limits:
    """What one server accepts: the token its clients must send (None: any), the largest
    message, how long it waits for each message."""

    token: str | None = None
    max_message_bytes: int = MAX_MESSAGE_BYTES
    idle_timeout_s: float = IDLE_TIMEOUT_S


def serve_connection(sock: socket.socket, limits: Limits = Limits()) -> None:
    """Run one bridge session on a connected socket until `bye`, the peer closes, a
    deadline passes or a message is malformed (answered with `error`, then closed)."""
    from addt_dsl.stack.bev import BevStack

    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    stack = ctx = None
    try:
        while True:
            deadline = time.monotonic() + limits.idle_timeout_s
            try:
                payload = recv_payload(sock, limits.max_message_bytes, deadline)
            except (ConnectionError, TimeoutError):
                return  # gone or idle: nothing to answer
            except (ProtocolError, OSError) as exc:
                _reply_error(sock, str(exc), deadline)
                return
            try:
                if ctx is None and limits.token is not None and not token_in_header(payload, limits.token):
                    # Before anything is parsed: a peer without the token costs no more than its bytes.
                    _reply_error(sock, "PermissionError: wrong or missing token", deadline)
                    return
                # Only a hello carries the map's text; every other header is small.
                header, blobs = decode(payload, None if ctx is None else MAX_HEADER_BYTES)
            except ProtocolError as exc:
                _reply_error(sock, str(exc), deadline)
                return
            kind = header.get("type")
            try:
                if kind == "hello":
                    if ctx is not None:
                        raise ValueError("a second hello on one connection")
                    _check_hello(header, limits)
                    ctx = RemoteContext(header)
                    stack = BevStack(header["stack"], ctx)
                    # As in process: faults learn the stack's sites (an unknown target is refused).
                    ctx.faults.bind(stack, lambda: ctx.now)
                    ready = {"type": "ready", "stack": "bev", "nodes": list(stack.latency)}
                    if header["protocol"] >= 2:  # the hello's protocol, and the faults it applies
                        ready.update(protocol=header["protocol"], faults=[k.fault.index for k in ctx.faults.kinds])
                    send(sock, ready, deadline=deadline)
                elif kind == "step":
                    if stack is None:
                        raise ValueError("step before hello")
                    reply, rblobs = _step(stack, ctx, header, blobs)
                    send(sock, reply, rblobs, deadline=deadline)
                elif kind == "bye":
                    return
                else:
                    raise ValueError(f"unknown message type {escape(str(kind), 80)!r}")
            except Exception as exc:  # noqa: BLE001 - reported to the simulator, which marks the run
                _reply_error(sock, f"{type(exc).__name__}: {exc}", deadline)
                return
    finally:
        if ctx is not None:
            ctx.faults.close()  # undo persistent side effects (flipped weights), as in process


def token_in_header(payload: bytes, token: str) -> bool:
    """Whether the unparsed header holds `"token": "<token>"` (as any JSON encoder writes
    it). Only a peer that knows the token can pass; `_check_hello` then compares the parsed
    field exactly."""
    try:
        head = header_bytes(payload)
    except ProtocolError:
        return False
    forms = {json.dumps(token).encode(), json.dumps(token, ensure_ascii=False).encode()}
    return any(re.search(rb'"token"\s*:\s*' + re.escape(form), head) for form in forms)


def _reply_error(sock: socket.socket, message: str, deadline: float) -> None:
    try:
        send(sock, {"type": "error", "message": escape(message)}, deadline=max(deadline, time.monotonic() + 1.0))
    except OSError:
        pass  # the peer is gone or not reading: closing is all that is left


def _check_hello(header: dict, limits: Limits) -> None:
    """The hello's token, protocol and settings, before anything is built from them."""
    if limits.token is not None and not hmac.compare_digest(str(header.get("token", "")).encode(),
                                                            limits.token.encode()):
        raise PermissionError("wrong or missing token")
    protocol = header.get("protocol")
    if isinstance(protocol, bool) or protocol not in PROTOCOLS:
        raise ValueError(f"protocol {escape(str(protocol), 40)} not supported "
                         f"(this server speaks {', '.join(map(str, PROTOCOLS))})")
    from addt_dsl.stack.bev import BevStack

    settings = header.get("stack")
    if not isinstance(settings, dict):
        raise ValueError("'stack' must be an object of settings")
    check_settings(settings, BevStack.params, "stack")
    step = header.get("step_s")
    if isinstance(step, bool) or not isinstance(step, (int, float)) or not 0.0 < step <= 1.0:
        raise ValueError("'step_s' must be a number in (0, 1] s")
    if not isinstance(header.get("seed"), int):
        raise ValueError("'seed' must be an integer")
    if protocol >= 2:
        _check_faults(header)
    elif "faults" in header:
        raise ValueError("'faults' needs protocol 2")
    if protocol >= SIGNALS_PROTOCOL:
        _check_signals(header)
    elif "stop_lines" in header or "signs" in header:
        raise ValueError("'stop_lines' and 'signs' need protocol 3")


def _station(d, what: str) -> float:
    if not isinstance(d, dict):
        raise ValueError(f"{what} must be an object")
    u = d.get("station_m")
    if isinstance(u, bool) or not isinstance(u, (int, float)) or not math.isfinite(u):
        raise ValueError(f"{what}: 'station_m' must be a finite number [m]")
    return float(u)


def _check_signals(header: dict) -> None:
    """Protocol 3: the stop lines (station and the light's controller) and the signs' lines
    (station and kind) on the ego's road or route."""
    for key in ("stop_lines", "signs"):
        items = header.get(key)
        if not isinstance(items, list) or len(items) > MAX_SIGNALS:
            raise ValueError(f"'{key}' must be a list of at most {MAX_SIGNALS} entries")
        for k, d in enumerate(items):
            _station(d, f"{key}[{k}]")
            if key == "stop_lines":
                c = d.get("controller")
                if not isinstance(c, str) or not 0 < len(c) <= 200:
                    raise ValueError(f"stop_lines[{k}]: 'controller' must be a name of 1 to 200 characters")
            elif not isinstance(d.get("kind"), str) or d["kind"] not in SIGN_KINDS:
                raise ValueError(f"signs[{k}]: 'kind' must be one of {', '.join(SIGN_KINDS)}")


_STATE_CODES = tuple(LIGHT_STATES.values())  # (a tuple: a peer's list or object is compared, not hashed)


def _light_states(ctx: RemoteContext, header: dict) -> dict[str, float]:
    """Protocol 3: each stop line's light's state code this step (0 green, 1 yellow, 2 red)."""
    lights = header.get("lights")
    if not isinstance(lights, dict):
        raise ValueError("a step of a run with stop lines must carry 'lights': each light's state code")
    states = {}
    for st in ctx.stop_lines:
        v = lights.get(st.controller)
        if isinstance(v, bool) or v not in _STATE_CODES:
            raise ValueError(f"'lights' must give light {escape(st.controller, 80)!r} a state code "
                             f"(0 green, 1 yellow, 2 red), not {escape(repr(v), 40)}")
        states[st.controller] = float(v)
    return states


def _check_faults(header: dict) -> None:
    """Protocol 2: the run's duration and its stack-internal faults, each a concrete
    schedule entry whose kind, window and settings are checked as the compiler would."""
    duration = header.get("duration_s")
    if isinstance(duration, bool) or not isinstance(duration, (int, float)) or not 0.0 < duration <= 1e6:
        raise ValueError("'duration_s' must be a number in (0, 1e6] s")
    faults = header.get("faults")
    if not isinstance(faults, list) or len(faults) > MAX_FAULTS:
        raise ValueError(f"'faults' must be a list of at most {MAX_FAULTS} faults")
    indices = set()
    for raw in faults:
        f = ConcreteFault.model_validate(raw)  # a pydantic ValidationError is a ValueError
        what = f"fault {f.index} ({escape(f.kind, 40)} {escape(f.target, 80)})"
        cls = FAULTS.get(f.kind)
        if cls is None or cls.target_kind == "sensor":
            raise ValueError(f"{what}: not a stack-internal fault kind (sensor faults act in the simulator)")
        if f.index in indices:
            raise ValueError(f"{what}: index given twice")
        indices.add(f.index)
        if not (math.isfinite(f.start_s) and f.start_s >= 0.0) or \
                (f.end_s is not None and not (math.isfinite(f.end_s) and f.end_s >= f.start_s)):
            raise ValueError(f"{what}: the window must be finite, from 0 s, and not end before it starts")
        if not 0 <= f.seed < 2**32:
            raise ValueError(f"{what}: the seed must be in [0, 2^32)")
        check_settings(f.settings, cls.params, what)


def check_settings(settings, params, what: str) -> None:
    """Settings against their ParamSpecs: known names, a word among its choices, a finite
    number in range (an integer where the spec says int)."""
    if not isinstance(settings, dict):
        raise ValueError(f"{what} settings must be an object")
    specs = {p.name: p for p in params}
    for key, value in settings.items():
        spec = specs.get(key)
        if spec is None:
            raise ValueError(f"unknown {what} setting {escape(str(key), 80)!r}")
        if spec.choices is not None:
            if value not in spec.choices:
                raise ValueError(f"{what} setting {key} must be one of {', '.join(spec.choices)}")
            continue
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ValueError(f"{what} setting {key} must be a finite number")
        if spec.kind == "int" and value != int(value):
            raise ValueError(f"{what} setting {key} must be an integer")
        if (spec.low is not None and value < spec.low) or (spec.high is not None and value > spec.high):
            raise ValueError(f"{what} setting {key}={value!r} is outside [{spec.low}, {spec.high}]")


def _step(stack, ctx: RemoteContext, header: dict, blobs: dict) -> tuple[dict, dict]:
    t = float(header["time_s"])
    ctx.now = t
    if t + 1e-12 >= ctx.faults.next_wake_s:  # fault timers, at the start of the step as in process
        ctx.faults.wake(t)
    if ctx.stop_lines:
        ctx.light_states = _light_states(ctx, header)
    e = header["ego"]
    ctx.ego = (e["x"], e["y"], e["heading"], e["speed"])
    ctx.ego_s = e["s_hint"]
    ctx.commands = []
    for f in header["frames"]:
        actors = None
        if "points" in f:
            truth = f.get("truth", {})
            hit = blobs[truth["hit_body"]] if "hit_body" in truth else np.zeros(0, dtype=np.int64)
            data = {"points": blobs[f["points"]], "hit_body": hit}
            sensor = ctx.sensors[f["sensor"]]
            sensor.actual = _Extrinsics(truth["actual"]) if "actual" in truth else sensor.nominal
            actors = {int(k): RemoteActor(v) for k, v in truth.get("actors", {}).items()}
        else:
            data = dict(f.get("values", {}))
            data.update({key: blobs[name] for key, name in f.get("arrays", {}).items()})
        # A client that sends no capture pose: the frame is taken as captured now.
        pose = tuple(float(v) for v in f["ego_pose"]) if "ego_pose" in f else ctx.ego
        stack.on_frame(RemoteFrame(f["sensor"], f["stamp_s"], data, pose, actors), f["arrive_s"])
    command = stack.step(t, float(header["dt"]))
    reply = {"type": "control", "command": list(command), "commands": ctx.commands,
             "latency": dict(stack.latency), "objects": stack.objects_seen, "events": _new_events(ctx)}
    series, blobs = _series(ctx)
    if series:
        reply["series"] = series
    return reply, blobs


def _new_events(ctx: RemoteContext) -> list:
    """The events since the last reply as `[time_s, kind, detail]`; a series fault event
    goes with empty columns, its entries follow in `series`."""
    out = []
    for seq in range(ctx.sent, len(ctx.events)):
        e = ctx.events[seq]
        detail = e.detail
        if e.kind == "fault" and "times" in detail:
            ctx.series_sent[seq] = 0
            detail = {k: ([] if k in SERIES_COLUMNS else v) for k, v in detail.items()}
        out.append([e.time_s, e.kind, detail])
    ctx.sent = len(ctx.events)
    return out


def _series(ctx: RemoteContext) -> tuple[list, dict]:
    """Entries added to series fault events since the last reply, as float64 blobs."""
    series, blobs = [], {}
    for seq, n in ctx.series_sent.items():
        detail = ctx.events[seq].detail
        if len(detail["times"]) == n:
            continue
        columns = {}
        for c in SERIES_COLUMNS:
            blobs[f"s{seq}.{c}"] = np.asarray(detail[c][n:], dtype="<f8")
            columns[c] = f"s{seq}.{c}"
        series.append([seq, columns])
        ctx.series_sent[seq] = len(detail["times"])
    return series, blobs


class _Handler(socketserver.BaseRequestHandler):
    def handle(self):
        server: BridgeServer = self.server  # type: ignore[assignment]
        if not server.slots.acquire(blocking=False):
            server.refuse(self.request, f"busy: {server.max_connections} runs already connected",
                         time.monotonic() + 1.0)
            return
        try:
            server.serve(self.request, server.limits)
        except Exception as exc:  # noqa: BLE001 - one bad session must not print a traceback
            print(f"bridge: session ended: {type(exc).__name__}: {escape(str(exc))}", file=sys.stderr)
        finally:
            server.slots.release()


class BridgeServer(socketserver.ThreadingTCPServer):
    daemon_threads = True
    allow_reuse_address = True

    def __init__(self, address: str, limits: Limits = Limits(), max_connections: int = MAX_CONNECTIONS,
                 serve=None, refuse=None):
        # One session on a connected socket, and the error reply to a connection over the
        # limit, in the server's protocol (the OSI server's differ).
        self.serve, self.refuse = serve or serve_connection, refuse or _reply_error
        host, port = parse_address(address, allow_port_zero=True)
        if ":" in host:  # an IPv6 address (`[::1]:5555`)
            self.address_family = socket.AF_INET6
        if not is_loopback(host):
            print(f"warning: the bridge server listens on {escape(host)}, not loopback: any host that can reach "
                  "it may drive the stack" + ("" if limits.token else "; set --token"), file=sys.stderr)
        self.limits = limits
        self.max_connections = max_connections
        self.slots = threading.BoundedSemaphore(max_connections)
        super().__init__((host, port), _Handler)

    @property
    def address(self) -> str:
        host, port = self.server_address[:2]
        return f"[{host}]:{port}" if ":" in host else f"{host}:{port}"


def start_in_thread(address: str = "127.0.0.1:0", limits: Limits = Limits(),
                    max_connections: int = MAX_CONNECTIONS, serve=None, refuse=None) -> BridgeServer:
    """A server on a background thread (for tests and notebooks); `shutdown()` it when done."""
    server = BridgeServer(address, limits, max_connections, serve, refuse)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server


def run_server_cli(argv, prog: str, description: str, default_address: str, serve=None, refuse=None,
                   max_message_bytes: int = MAX_MESSAGE_BYTES, idle_timeout_s: float = IDLE_TIMEOUT_S) -> int:
    """The command line of a reference server (this one, the OSI server): address, token and
    limits, then serve until interrupted; a bad address or a port in use is one line, exit 2."""
    ap = argparse.ArgumentParser(prog=prog, description=description)
    ap.add_argument("--address", default=default_address, help="HOST:PORT to listen on (port 0: any free one)")
    ap.add_argument("--token", default=os.environ.get(TOKEN_ENV),
                    help=f"shared token every hello must carry (default: ${TOKEN_ENV}, else none)")
    ap.add_argument("--max-message-bytes", type=int, default=max_message_bytes,
                    help="largest message accepted, checked before it is read")
    ap.add_argument("--idle-timeout", type=float, default=idle_timeout_s,
                    help="seconds to wait for each whole message before closing the connection")
    ap.add_argument("--max-connections", type=int, default=MAX_CONNECTIONS, help="runs served at once")
    args = ap.parse_args(argv)
    limits = Limits(args.token or None, args.max_message_bytes, args.idle_timeout)
    try:
        server = BridgeServer(args.address, limits, args.max_connections, serve, refuse)
    except (ValueError, OSError) as exc:  # a bad address, a port in use: one line, not a traceback
        print(f"error: cannot listen on {escape(args.address, 200)}: {exc}", file=sys.stderr)
        return 2
    with server:
        print(f"listening {server.address}", flush=True)
        try:
            server.serve_forever()
        except KeyboardInterrupt:
            pass
    return 0


def main(argv=None) -> int:
    return run_server_cli(argv, "python -m addt_dsl.stack.bridge_server", __doc__.split("\n")[0], "127.0.0.1:5555")

if __name__ == "__main__":
    sys.exit(main())
