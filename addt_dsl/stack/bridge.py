"""`stack external`: drive a stack that runs in another process over a socket (see docs/bridge.md).

Like the paper's Jetson on Ethernet, but lock-step in simulated time: every physics step
the simulator sends the step's sensor frames and the ego state and waits for the stack's
reply (the commands it publishes and when they take effect). A deterministic remote
stack therefore gives a deterministic run, whatever the wall-clock speed of either side.

Wire format (protocols 1 to 3), both directions, one message at a time over TCP:

    u32 big-endian: length of the rest | u32 big-endian: header length | header | blobs

The header is a UTF-8 JSON object with a "type"; binary arrays follow it back to back,
described in order by `header["blobs"]` = [{"name", "dtype" (numpy, little-endian),
"shape"}]. Floats in JSON are written with Python's shortest round-trip repr, so they
arrive bit for bit.

The client side (`ExternalStack`) is the registered stack; the message helpers here are
shared with the reference server `addt_dsl.stack.bridge_server`.

Protocol 2 adds stack-internal faults: a run with faults on the stack's sites, state sites,
tensors or nodes (bit flips, stuck values, latency spikes) sends them in `hello` as concrete
schedule entries; the remote applies them with its own copy of the fault machinery and
returns each injection as a `fault` event with its replies. Protocol 3 adds what the
in-process stack reads of the map's signals: the stations of the traffic lights' stop lines
and of the signs' lines (with their kinds) on the ego's road or route in `hello`, each light's state in
every `step`. A hello says the lowest protocol that carries what its run has (1: neither
faults nor signals; 2: faults; 3: signals), so older servers still serve the runs they can.
"""

from __future__ import annotations

import importlib

import ipaddress
import json
import math
import os
import socket
import struct
import time

import numpy as np

from addt_dsl.registry import STACKS
from addt_dsl.specs import stacks as S
from addt_dsl.specs.stacks import CLIENT_SETTINGS, escape, parse_address
from addt_dsl.runtime.signs import SIGN_KINDS
from addt_dsl.runtime.trace import SERIES_COLUMNS, Event
from addt_dsl.stack.bev import NODE_NAMES, StackError

PROTOCOL = 3  # the newest protocol; a hello says the lowest that carries what its run has
FAULTS_PROTOCOL = 2  # stack-internal faults in `hello`
SIGNALS_PROTOCOL = 3  # stop lines and signs in `hello`, the lights' states in `step`
PROTOCOLS = (1, 2, 3)  # what the reference server accepts
MAX_FAULTS = 1000  # stack-internal faults one hello may carry
MAX_SIGNALS = 10_000  # stop lines, and signs, one hello may carry (each)
_HEAD = struct.Struct(">II")


# ---------------------------------------------------------------- framing

def encode(header: dict, blobs: dict[str, np.ndarray] | None = None) -> bytes:
    """One message: header JSON plus named little-endian arrays."""
    header = dict(header)
    parts = []
    if blobs:
        desc = []
        for name, arr in blobs.items():
            arr = np.ascontiguousarray(arr)
            arr = arr.astype(arr.dtype.newbyteorder("<"), copy=False)
            desc.append({"name": name, "dtype": arr.dtype.str, "shape": list(arr.shape)})
            parts.append(arr.tobytes())
        header["blobs"] = desc
    head = json.dumps(header, separators=(",", ":"), allow_nan=True).encode()
    body = b"".join(parts)
    return _HEAD.pack(4 + len(head) + len(body), len(head)) + head + body


class ProtocolError(ValueError):
    """A message that breaks the framing or the schema: the connection is closed."""


MAX_MESSAGE_BYTES = 64 * 2**20  # default limit on one message, checked before it is read
# Limits on the JSON header, checked on its bytes before it is parsed: parsed JSON costs up
# to ~30x its size (a 60 MiB reply of `[{},{},...]` took 1.8 GB). Blobs cost their size.
MAX_HEADER_BYTES = 4 * 2**20  # a step or a reply (a hello may be larger: it carries the map's text)
MAX_JSON_CONTAINERS = 100_000  # `{` and `[` bytes in one header (objects and lists; a bound from above)
# Bounds on what one reply may ask of the run (a reply of 20,000 events per step turned a 6 s
# run into 245 s and exit 3): more is a stack failure (the run is detected).
MAX_COMMANDS_PER_STEP = 100
MAX_EVENTS_PER_STEP = 2 * MAX_FAULTS  # every fault injecting at once, and as many stack events
MAX_EVENTS_PER_RUN = 200_000
MAX_LATENCY_S = 3600.0  # the largest `timeout` setting: a latency beyond it cannot have been waited for
MAX_APPLY_DELAY_S = 3600.0  # a command takes effect at most this long after its step
MAX_OBJECTS = 1_000_000
_BLOB_KINDS = "biuf"  # numeric dtypes only (never object or void arrays)


def header_bytes(payload: bytes) -> bytes:
    """The JSON header of a message (the bytes after the length prefix), unparsed."""
    if len(payload) < 4:
        raise ProtocolError("message shorter than its header length")
    (head_len,) = struct.unpack(">I", payload[:4])
    if 4 + head_len > len(payload):
        raise ProtocolError("header length runs past the message")
    return payload[4:4 + head_len]


def decode(payload: bytes, max_header_bytes: int | None = MAX_HEADER_BYTES,
           max_containers: int = MAX_JSON_CONTAINERS) -> tuple[dict, dict[str, np.ndarray]]:
    """Inverse of `encode` for the bytes after the length prefix; ProtocolError on any
    malformed input (bad JSON, a header that is not an object, blobs that do not fit) and
    on a header beyond the limits, refused before it is parsed."""
    head = header_bytes(payload)
    head_len = len(head)
    if max_header_bytes is not None and head_len > max_header_bytes:
        raise ProtocolError(f"message header of {head_len} bytes exceeds the limit of {max_header_bytes} bytes")
    containers = head.count(b"{") + head.count(b"[")
    if containers > max_containers:
        raise ProtocolError(f"message header has {containers} objects or lists (brackets), beyond the limit of "
                            f"{max_containers}")
    try:
        header = json.loads(head)
        if not isinstance(header, dict):
            raise ProtocolError("the header is not a JSON object")
        descs = header.pop("blobs", [])
        if not isinstance(descs, list):
            raise ProtocolError("'blobs' is not a list")
        blobs = {}
        offset = 4 + head_len
        for d in descs:
            dtype = np.dtype(d["dtype"])
            shape = [int(n) for n in d["shape"]]
            if dtype.kind not in _BLOB_KINDS or any(n < 0 for n in shape) or not isinstance(d["name"], str):
                raise ProtocolError(f"blob {escape(str(d.get('name')))!r}: unsupported dtype or shape")
            n = math.prod(shape) * dtype.itemsize
            if offset + n > len(payload):
                raise ProtocolError("blobs run past the message")
            blobs[d["name"]] = np.frombuffer(payload[offset:offset + n], dtype=dtype).reshape(shape)
            offset += n
    except ProtocolError:
        raise
    except (ValueError, TypeError, KeyError, AttributeError, RecursionError, struct.error) as exc:
        raise ProtocolError(f"malformed message: {type(exc).__name__}: {escape(str(exc))}") from None
    if offset != len(payload):
        raise ProtocolError(f"message has {len(payload) - offset} trailing bytes")
    return header, blobs


def recv_exact(sock: socket.socket, n: int, deadline: float | None) -> bytes:
    """Read n bytes before `deadline` (time.monotonic()): the deadline bounds the whole
    message, so a peer trickling one byte a second still times out."""
    buf = bytearray(n)
    view = memoryview(buf)
    got = 0
    while got < n:
        if deadline is not None:
            left = deadline - time.monotonic()
            if left <= 0:
                raise TimeoutError("the peer did not send a whole message in time")
            sock.settimeout(left)
        k = sock.recv_into(view[got:], n - got)
        if k == 0:
            raise ConnectionError("peer closed the connection")
        got += k
    return bytes(buf)


def send(sock: socket.socket, header: dict, blobs: dict[str, np.ndarray] | None = None,
         deadline: float | None = None) -> None:
    if deadline is not None:
        left = deadline - time.monotonic()
        if left <= 0:
            raise TimeoutError("no time left to send")
        sock.settimeout(left)
    sock.sendall(encode(header, blobs))


def recv_payload(sock: socket.socket, max_bytes: int = MAX_MESSAGE_BYTES, deadline: float | None = None) -> bytes:
    """One message's bytes after its length prefix, unparsed; refused (ProtocolError) if
    the prefix exceeds `max_bytes` before any of it is read."""
    (length,) = struct.unpack(">I", recv_exact(sock, 4, deadline))
    if length > max_bytes:
        raise ProtocolError(f"message of {length} bytes exceeds the limit of {max_bytes} bytes")
    if length < 4:
        raise ProtocolError(f"message of {length} bytes is shorter than its header length")
    return recv_exact(sock, length, deadline)


def recv(sock: socket.socket, max_bytes: int = MAX_MESSAGE_BYTES, deadline: float | None = None,
         max_header_bytes: int | None = MAX_HEADER_BYTES) -> tuple[dict, dict[str, np.ndarray]]:
    """One message, within `max_bytes` (checked before it is read) and the header limits
    (checked before it is parsed)."""
    return decode(recv_payload(sock, max_bytes, deadline), max_header_bytes)


ALLOW_HOSTS_ENV = "ADDT_BRIDGE_ALLOW_HOSTS"  # comma-separated; `addtc run --allow-host HOST` sets it
TOKEN_ENV = "ADDT_BRIDGE_TOKEN"  # the shared token both sides send and expect in `hello`


def is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback  # IPv6 without brackets (`parse_address`)
    except ValueError:
        return False  # any other name could resolve anywhere


def allowed_hosts() -> set[str]:
    return {h.strip() for h in os.environ.get(ALLOW_HOSTS_ENV, "").split(",") if h.strip()}


def check_address(host: str) -> None:
    """A scenario file may only point the runner at this machine, unless the person
    running it allowed the host on the command line."""
    if not is_loopback(host) and not {host, f"[{host}]"} & allowed_hosts():
        raise StackError(f"refused to connect to {escape(host)!r}: a scenario's bridge address must be loopback "
                         f"unless allowed with `addtc run --allow-host {escape(host)}`")


def extrinsics_dict(ext) -> dict[str, float]:
    return {k: float(getattr(ext, k)) for k in ("x", "y", "z", "roll", "pitch", "yaw")}


# ---------------------------------------------------------------- the client stack



def _osi_stack():
    # The OSI client subclasses ExternalStack and needs osi3 (the `osi` extra): loaded by name
    # only when a scenario asks for it, so this module does not import its own subclass.
    return importlib.import_module("addt_dsl.stack.osi_stack").OsiStack


# `stack external protocol WORD` -> the client class that speaks it (ExternalStack or a subclass).
PROTOCOL_CLIENTS = {"bridge": lambda: ExternalStack, "osi": _osi_stack}


@STACKS.implements
class ExternalStack(S.ExternalStack):
    """A stack in another process behind the bridge; the remote's own settings pass through."""

    def __new__(cls, settings: dict | None = None, ctx=None):
        # `protocol osi` runs the OSI client (a subclass): the registered stack stays one.
        impl = PROTOCOL_CLIENTS[str((settings or {}).get("protocol", "bridge"))]() if cls is ExternalStack else cls
        return object.__new__(impl)

    def __init__(self, settings: dict, ctx):
        self.settings = {p.name: settings.get(p.name, p.default) for p in self.params}
        self.ctx = ctx
        self.internal_faults: list = []  # ConcreteFaults the remote applies (protocol 2)
        self._remote_events: list = []  # every event the remote sent, in order: series grow in place
        self.latency = {n: 0.0 for n in (*NODE_NAMES, "e2e")}
        self.objects_seen = 0
        self._frames: list = []
        self._controllers: list[str] = []  # the lights whose states each step sends (protocol 3)
        self.sock = None  # connected at the first step, so a failure there is a detected stack failure

    def _connect(self) -> None:
        if self.internal_faults and self.sites_of(self.settings) is None:
            # The compiler refuses this (E0109); a RunSpec built by hand ends here, detected.
            raise StackError(f"`stack external sites none` declares no fault sites, but the run has "
                             f"{self._faults_text()}")
        try:
            host, port = parse_address(str(self.settings["address"]))
        except ValueError as exc:  # the compiler refuses these (E0204); a hand-built RunSpec ends here
            raise StackError(f"external stack address: {exc}") from None
        check_address(host)
        timeout = float(self.settings["timeout"])
        try:
            self.sock = socket.create_connection((host, port), timeout=timeout)
        except OSError as exc:
            raise StackError(f"cannot reach the external stack at {escape(host)}:{port}: {exc}") from None
        try:
            self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            hello = self._bridge_hello()
            try:
                ready, _ = self._request(hello, expect="ready")
            except StackError as exc:
                if hello["protocol"] == 1 or "protocol" not in str(exc):
                    raise
                raise StackError(f"{exc} ({self._needs_text(hello['protocol'])})") from None
            self._check_ready(ready, hello["protocol"])
        except BaseException:
            self.sock.close()
            self.sock = None
            raise

    def take_internal_faults(self, faults) -> None:
        """The run's faults on stack sites, state sites, tensors and nodes (`FaultSchedule.bind`
        hands them over): sent to the remote in `hello`, applied there."""
        self.internal_faults = list(faults)

    def _faults_text(self) -> str:
        names = [f"{f.kind} {f.target}" for f in self.internal_faults[:3]]
        more = len(self.internal_faults) - len(names)
        return "stack-internal faults (" + ", ".join(names) + (f", {more} more" if more else "") + ")"

    def _needs_text(self, protocol: int) -> str:
        """Why a hello said `protocol` (2 or 3), for a server that refused it."""
        if protocol == SIGNALS_PROTOCOL:
            return (f"this run's {self._signals_text()} need bridge protocol 3; a server that speaks only "
                    "protocols 1 and 2 cannot tell its stack of them")
        return (f"this run's {self._faults_text()} need bridge protocol 2; a server that speaks only "
                "protocol 1 cannot apply them")

    def _signals_text(self) -> str:
        lines, signs = self.ctx.ego_light_stations(), self.ctx.ego_sign_stations()
        parts = []
        if lines:
            names = ", ".join(dict.fromkeys(c for _, c in lines))
            parts.append(f"traffic lights ({escape(names, 200)})")
        for kind in SIGN_KINDS:
            n = sum(k == kind for _, k in signs)
            if n:
                parts.append(f"{n} {kind} sign{'s' if n > 1 else ''}")
        return " and ".join(parts) + " on the ego's route"

    def _check_ready(self, ready: dict, protocol: int) -> None:
        """A hello with faults must be answered by a remote that took every one of them:
        a stack that ignores them would let the run pass as if it had been faulted. (A stack
        may ignore the signals of protocol 3: running a red light is its own failure, which
        the run's oracles judge.)"""
        if not self.internal_faults:
            return
        sent = sorted(f.index for f in self.internal_faults)
        taken = ready.get("faults")
        if ready.get("protocol") != protocol or not isinstance(taken, list) or \
                not all(type(t) is int for t in taken) or sorted(taken) != sent:
            raise StackError(f"the external stack did not confirm this run's {self._faults_text()}: its `ready` "
                             f"says protocol {escape(str(ready.get('protocol', 1)), 20)} and faults "
                             f"{escape(repr(taken), 200)}, expected protocol {protocol} and {sent} (docs/bridge.md)")

    def _hello(self) -> dict:
        """What every protocol's hello says (the OSI client's too): the run, the ego, its
        sensors, the map, the remote's settings, the token."""
        ctx = self.ctx
        spec, ego_plan = ctx.spec, ctx.ego_plan
        road = spec.plan.road(ego_plan.road)
        remote = {k: v for k, v in self.settings.items() if k not in CLIENT_SETTINGS}
        sensors = [{"name": name, "kind": s.keyword, "settings": jsonable(s.settings),
                    "nominal": extrinsics_dict(s.nominal), "period_s": s.period_s}
                   for name, s in ctx.sensors.items()]
        hello = {
            "type": "hello", "protocol": 1, "seed": spec.seed, "step_s": ctx.step_s,
            "stack": jsonable(remote),
            # `route`, `map_lane`, `s_m`: the ego's path as the map names it, so the remote
            # plans along the same route (its lane id on the first road, its start station).
            "ego": {"lane": ctx.ego_lane, "route": list(ego_plan.route), "map_lane": ego_plan.lane,
                    "s_m": ego_plan.s, "wheelbase_m": ctx.wheelbase_m,
                    "length_m": ego_plan.length_m, "width_m": ego_plan.width_m,
                    "mass_kg": ego_plan.mass_kg, "mu": ego_plan.mu},
            "sensors": sensors,
            "map": {"format": "addt-road-plan", "road": road.model_dump(mode="json")},
        }
        token = os.environ.get(TOKEN_ENV)
        if token:
            hello["token"] = token
        return hello

    def _bridge_hello(self) -> dict:
        """The bridge's hello, in the lowest protocol that carries what the run has, so
        older servers serve the runs they can: 2 for stack-internal faults, 3 for the stop
        lines and the signs on the ego's route (the in-process stack reads them from the
        map: `stop_line_ahead`, `stop_sign_ahead`, `junction_rule`)."""
        ctx = self.ctx
        hello = self._hello()
        lines, signs = ctx.ego_light_stations(), ctx.ego_sign_stations()
        if self.internal_faults or lines or signs:
            hello.update(protocol=SIGNALS_PROTOCOL if lines or signs else FAULTS_PROTOCOL,
                         duration_s=ctx.duration_s,
                         faults=[f.model_dump(mode="json") for f in self.internal_faults])
        if lines or signs:
            hello.update(stop_lines=[{"station_m": float(u), "controller": c} for u, c in lines],
                         signs=[{"station_m": float(u), "kind": k} for u, k in signs])
        # The controllers whose states each step carries (in their first line's order).
        self._controllers = list(dict.fromkeys(c for _, c in lines))
        return hello

    def _request(self, header: dict, blobs=None, expect: str = "control"):
        """Send one message and read its reply, all within the `timeout` setting."""
        deadline = time.monotonic() + float(self.settings["timeout"])
        try:
            send(self.sock, header, blobs, deadline)
            reply, rblobs = recv(self.sock, deadline=deadline)
        except (OSError, ConnectionError, ValueError) as exc:  # TimeoutError is an OSError
            raise StackError(f"external stack: {type(exc).__name__}: {escape(str(exc))}") from None
        if reply.get("type") == "error":
            raise StackError(f"external stack error: {escape(str(reply.get('message', '')))}")
        if reply.get("type") != expect:
            raise StackError(f"external stack sent {escape(str(reply.get('type')))!r}, expected {expect!r}")
        return reply, rblobs

    # ---- the stack interface the loop drives
    def on_frame(self, frame, arrive_s: float) -> None:
        self._frames.append((frame, arrive_s))

    def step(self, time_s: float, dt: float):
        self.ctx.now = time_s
        frames, blobs = [], {}
        for k, (frame, arrive_s) in enumerate(self._frames):
            entry = {"sensor": frame.sensor, "stamp_s": frame.stamp_s, "arrive_s": arrive_s}
            data = frame.data
            if "points" in data:
                blobs[f"{k}.points"] = np.asarray(data["points"], dtype="<f8")
                entry["points"] = f"{k}.points"
                # Ground truth for a remote ground-truth perception (a real stack ignores it).
                hit = np.asarray(data.get("hit_body", np.zeros(0)), dtype="<i8")
                blobs[f"{k}.hit_body"] = hit
                sensor = self.ctx.sensor(frame.sensor)
                entry["truth"] = {"hit_body": f"{k}.hit_body", "actual": extrinsics_dict(sensor.actual),
                                  "actors": _actors(frame.actors or {})}
            else:
                # Other sensors: arrays (camera images, IMU vectors) as blobs, scalars inline.
                arrays = {key: v for key, v in data.items() if isinstance(v, np.ndarray)}
                for key, arr in arrays.items():
                    blobs[f"{k}.{key}"] = arr
                entry["arrays"] = {key: f"{k}.{key}" for key in arrays}
                entry["values"] = jsonable({key: v for key, v in data.items() if key not in arrays})
            if frame.ego_pose is not None:  # where the ego was at the capture
                entry["ego_pose"] = [float(v) for v in frame.ego_pose]
            frames.append(entry)
        self._frames = []
        x, y, heading, speed = self.ctx.ego_pose()
        ego = {"x": x, "y": y, "heading": heading, "speed": speed, "s_hint": self.ctx.ego_station()}
        if self.sock is None:
            self._connect()
        header = {"type": "step", "time_s": time_s, "dt": dt, "ego": ego, "frames": frames}
        if self._controllers:
            # Each light's state now, which the in-process stack reads as it plans this step.
            header["lights"] = {c: float(self.ctx.light_state(c, time_s)) for c in self._controllers}
        reply, rblobs = self._request(header, blobs)
        command, commands, latency, objects, events = _control(reply, time_s, dt)
        if len(self._remote_events) + len(events) > MAX_EVENTS_PER_RUN:
            raise StackError(f"external stack sent more than {MAX_EVENTS_PER_RUN} events in one run")
        for apply_s, steer, accel in commands:
            self.ctx.apply_command_at(apply_s, steer, accel)
        for name, value in latency.items():
            if name in self.latency:
                self.latency[name] = value
        self.objects_seen = objects
        for t, kind, detail in events:
            event = _event(t, kind, detail)
            self._remote_events.append(event)
            self.ctx.emit(event)
        if "series" in reply:
            _grow_series(reply["series"], rblobs, self._remote_events)
        return command

    def close(self) -> None:
        if getattr(self, "sock", None) is None:
            return
        try:
            send(self.sock, {"type": "bye"})
        except OSError:
            pass
        self.sock.close()
        self.sock = None


def _control(reply: dict, time_s: float, dt: float = 0.0):
    """The fields of a `control` reply, checked: a number that is not finite (a NaN command
    time would never be applied and block every later command), outside its bounds (a
    command to apply before this step, a latency of 1e308 s, 20,000 events) or a malformed
    field is a stack failure (StackError, the run is *detected*); peer text is escaped.
    Command values themselves are the vehicle's to clip, as in process (a bit flip in the
    stack's control makes the same)."""
    def number(v, what: str, lo: float = -math.inf, hi: float = math.inf) -> float:
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise StackError(f"external stack sent a non-finite or non-numeric {what}: {escape(repr(v))}")
        if not lo <= v <= hi:
            raise StackError(f"external stack sent {what} {escape(repr(v), 40)}, outside [{lo:g}, {hi:g}]")
        return float(v)

    def bounded(items, limit: int, what: str) -> list:
        if not isinstance(items, list):
            raise StackError(f"external stack sent malformed {what}: not a list")
        if len(items) > limit:
            raise StackError(f"external stack sent {len(items)} {what} in one step, more than {limit}")
        return items

    def applied(c) -> tuple:
        apply_s, steer, accel = triple(c, "command")
        apply_s = number(apply_s, "command time [s]", time_s - 1e-9, time_s + MAX_APPLY_DELAY_S)
        return apply_s, number(steer, "command steer"), number(accel, "command accel")

    def triple(v, what: str):
        if not isinstance(v, (list, tuple)) or len(v) != 3:
            raise StackError(f"external stack sent a malformed {what}: {escape(repr(v))}")
        return v

    try:
        raw = reply.get("command", (0.0, 0.0))
        if not isinstance(raw, (list, tuple)) or len(raw) != 2:
            raise StackError(f"external stack sent a malformed command: {escape(repr(raw))}")
        command = (number(raw[0], "command steer"), number(raw[1], "command accel"))
        commands = [applied(c) for c in bounded(reply.get("commands", []), MAX_COMMANDS_PER_STEP, "commands")]
        raw_latency = dict(reply.get("latency", {}))
        if len(raw_latency) > 64:
            raise StackError(f"external stack sent {len(raw_latency)} latency entries, more than 64")
        latency = {escape(str(k), 80): number(v, "latency [s]", 0.0, MAX_LATENCY_S) for k, v in raw_latency.items()}
        objects = number(reply.get("objects", 0), "object count", 0, MAX_OBJECTS)
        if objects != int(objects):
            raise StackError(f"external stack sent a fractional object count: {objects!r}")
        objects = int(objects)
        events = []
        for e in bounded(reply.get("events", []), MAX_EVENTS_PER_STEP, "events"):
            t, kind, detail = triple(e, "event")
            events.append((number(t, "event time [s]", 0.0, time_s + dt + 1e-9), escape(str(kind), 80),
                           _escaped(dict(detail))))
    except (TypeError, ValueError, AttributeError) as exc:
        raise StackError(f"external stack sent a malformed control reply: {escape(str(exc))}") from None
    return command, commands, latency, objects, events


def _grow_series(series, blobs: dict, events: list) -> None:
    """New entries of the remote's series fault events (`random_value`: one event per
    site whose columns grow with every injection). `series` is `[[event, {column: blob}]]`,
    `event` the position of the series event among all events the remote sent; the
    columns travel as float64 blobs, so they arrive bit for bit."""
    try:
        for seq, columns in series:
            if isinstance(seq, bool) or not isinstance(seq, int) or not 0 <= seq < len(events):
                raise StackError(f"external stack sent series entries for event {escape(repr(seq), 40)}, "
                                 f"which it never sent")
            detail = events[seq].detail
            if events[seq].kind != "fault" or not all(isinstance(detail.get(c), list) for c in SERIES_COLUMNS):
                raise StackError(f"external stack sent series entries for event {seq}, which is not a series")
            arrays = [blobs.get(columns[c]) for c in SERIES_COLUMNS]
            if any(a is None or a.ndim != 1 or a.dtype.kind != "f" for a in arrays) or \
                    len({len(a) for a in arrays}) != 1:
                raise StackError(f"external stack sent malformed series entries for event {seq}")
            for c, a in zip(SERIES_COLUMNS, arrays):
                detail[c].extend(a.astype("<f8").tolist())
    except (TypeError, ValueError, KeyError, AttributeError) as exc:
        raise StackError(f"external stack sent malformed series entries: {escape(str(exc))}") from None


def _escaped(value, depth: int = 0):
    """A peer's JSON value with every string escaped (for events stored in the trace)."""
    if depth > 8:
        return escape(repr(value), 200)
    if isinstance(value, str):
        return escape(value, 500)
    if isinstance(value, dict):
        return {escape(str(k), 80): _escaped(v, depth + 1) for k, v in value.items()}
    if isinstance(value, list):
        return [_escaped(v, depth + 1) for v in value]
    return value


def _event(t, kind, detail):
    return Event(float(t), str(kind), dict(detail))


def jsonable(d: dict) -> dict:
    out = {}
    for k, v in d.items():
        if isinstance(v, np.generic):
            v = v.item()
        elif isinstance(v, np.ndarray):
            v = v.tolist()
        out[k] = v
    return out


def _actors(actors: dict) -> dict[str, dict]:
    """The ground truth a lidar frame captured (body id -> actor), as the protocol sends it."""
    return {str(body): {"x": gt.x, "y": gt.y, "heading": gt.heading, "speed": gt.speed,
                        "length_m": gt.length_m, "width_m": gt.width_m, "kind": gt.kind}
            for body, gt in actors.items() if gt is not None}
