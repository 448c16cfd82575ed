"""`stack external`: drive a stack that runs in another process over a socket (see docs/bridge.md).

Like the paper's Jetson on Ethernet, but lock-step in simulated time: every physics step
the simulator sends the step's sensor frames and the ego state and waits for the stack's
reply (the commands it publishes and when they take effect). A deterministic remote
stack therefore gives a deterministic run, whatever the wall-clock speed of either side.

Wire format (protocol 1), both directions, one message at a time over TCP:

    u32 big-endian: length of the rest | u32 big-endian: header length | header | blobs

The header is a UTF-8 JSON object with a "type"; binary arrays follow it back to back,
described in order by `header["blobs"]` = [{"name", "dtype" (numpy, little-endian),
"shape"}]. Floats in JSON are written with Python's shortest round-trip repr, so they
arrive bit for bit.

The client side (`ExternalStack`) is the registered stack; the message helpers here are
shared with the reference server `addt_dsl.stack.bridge_server`.
"""

from __future__ import annotations

import json
import math
import socket
import struct

import numpy as np

from addt_dsl import units
from addt_dsl.registry import STACKS, ParamSpec
from addt_dsl.stack.bev import NODE_NAMES, BevStack, StackError

PROTOCOL = 1
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


def decode(payload: bytes) -> tuple[dict, dict[str, np.ndarray]]:
    """Inverse of `encode` for the bytes after the length prefix."""
    (head_len,) = struct.unpack(">I", payload[:4])
    header = json.loads(payload[4:4 + head_len])
    blobs = {}
    offset = 4 + head_len
    for d in header.pop("blobs", []):
        dtype = np.dtype(d["dtype"])
        n = int(np.prod(d["shape"], dtype=np.int64)) * dtype.itemsize
        blobs[d["name"]] = np.frombuffer(payload[offset:offset + n], dtype=dtype).reshape(d["shape"])
        offset += n
    if offset != len(payload):
        raise ValueError(f"message has {len(payload) - offset} trailing bytes")
    return header, blobs


def _recv_exact(sock: socket.socket, n: int) -> bytes:
    buf = bytearray(n)
    view = memoryview(buf)
    got = 0
    while got < n:
        k = sock.recv_into(view[got:], n - got)
        if k == 0:
            raise ConnectionError("peer closed the connection")
        got += k
    return bytes(buf)


def send(sock: socket.socket, header: dict, blobs: dict[str, np.ndarray] | None = None) -> None:
    sock.sendall(encode(header, blobs))


def recv(sock: socket.socket) -> tuple[dict, dict[str, np.ndarray]]:
    (length,) = struct.unpack(">I", _recv_exact(sock, 4))
    return decode(_recv_exact(sock, length))


def parse_address(address: str) -> tuple[str, int]:
    host, sep, port = address.rpartition(":")
    if not sep or not port.isdigit():
        raise ValueError(f"address must be HOST:PORT, not {address!r}")
    return host or "127.0.0.1", int(port)


def extrinsics_dict(ext) -> dict[str, float]:
    return {k: float(getattr(ext, k)) for k in ("x", "y", "z", "roll", "pitch", "yaw")}


# ---------------------------------------------------------------- the client stack

@STACKS.register
class ExternalStack:
    """A stack in another process behind the bridge; the remote's own settings pass through."""

    keyword = "external"
    # Settings of the default stack pass through to the remote (the reference server
    # hosts `bev`); a user's stack reads what it understands.
    params = (
        ParamSpec("address", None, kind="string", default="127.0.0.1:5555",
                  doc="HOST:PORT of the remote stack's bridge server"),
        ParamSpec("timeout", units.TIME, default=30.0, low=0.001, high=3600.0,
                  doc="wall-clock wait for each reply before the run is marked detected"),
        *BevStack.params,
    )
    nodes = {name: () for name in NODE_NAMES}
    doc = "A stack in another process or language, lock-step over a socket (docs/bridge.md)."

    @classmethod
    def fault_sites(cls, settings: dict | None = None) -> set[str]:
        return set()  # the remote's internals are out of reach; sensor and timing faults still apply

    def __init__(self, settings: dict, ctx):
        self.settings = {p.name: settings.get(p.name, p.default) for p in self.params}
        self.ctx = ctx
        self.latency = {n: 0.0 for n in (*NODE_NAMES, "e2e")}
        self.objects_seen = 0
        self._frames: list = []
        host, port = parse_address(str(self.settings["address"]))
        timeout = float(self.settings["timeout"])
        try:
            self.sock = socket.create_connection((host, port), timeout=timeout)
        except OSError as exc:
            raise StackError(f"cannot reach the external stack at {host}:{port}: {exc}") from None
        try:
            self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._request(self._hello(), expect="ready")
        except BaseException:
            self.sock.close()  # the run never gets this stack to close
            raise

    def _hello(self) -> dict:
        run = self.ctx.run
        spec = run.spec
        road = spec.plan.road(run.ego_plan.road)
        remote = {k: v for k, v in self.settings.items() if k not in ("address", "timeout")}
        sensors = [{"name": name, "kind": s.keyword, "settings": _jsonable(s.settings),
                    "nominal": extrinsics_dict(s.nominal), "period_s": s.period_s}
                   for name, s in run.sensors.items()]
        return {
            "type": "hello", "protocol": PROTOCOL, "seed": spec.seed, "step_s": run.dt,
            "stack": _jsonable(remote),
            "ego": {"lane": self.ctx.ego_lane, "wheelbase_m": self.ctx.wheelbase_m,
                    "length_m": run.ego_plan.length_m, "width_m": run.ego_plan.width_m},
            "sensors": sensors,
            "map": {"format": "addt-road-plan", "road": road.model_dump(mode="json")},
        }

    def _request(self, header: dict, blobs=None, expect: str = "control"):
        try:
            send(self.sock, header, blobs)
            reply, rblobs = recv(self.sock)
        except (OSError, ConnectionError, ValueError) as exc:
            raise StackError(f"external stack: {type(exc).__name__}: {exc}") from None
        if reply.get("type") == "error":
            raise StackError(f"external stack error: {reply.get('message', '')}")
        if reply.get("type") != expect:
            raise StackError(f"external stack sent {reply.get('type')!r}, expected {expect!r}")
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
                                  "actors": self._actors(hit)}
            else:
                # Other sensors: arrays (camera images, IMU vectors) as blobs, scalars inline.
                arrays = {key: v for key, v in data.items() if isinstance(v, np.ndarray)}
                for key, arr in arrays.items():
                    blobs[f"{k}.{key}"] = arr
                entry["arrays"] = {key: f"{k}.{key}" for key in arrays}
                entry["values"] = _jsonable({key: v for key, v in data.items() if key not in arrays})
            frames.append(entry)
        self._frames = []
        x, y, heading, speed = self.ctx.ego_pose()
        ego = {"x": x, "y": y, "heading": heading, "speed": speed, "s_hint": self.ctx.run.ego_s}
        reply, _ = self._request({"type": "step", "time_s": time_s, "dt": dt, "ego": ego, "frames": frames},
                                 blobs)
        for apply_s, steer, accel in reply.get("commands", []):
            if not (math.isfinite(steer) and math.isfinite(accel)):
                raise StackError(f"non-finite command steer={steer!r} accel={accel!r}")
            self.ctx.apply_command_at(float(apply_s), float(steer), float(accel))
        for name, value in reply.get("latency", {}).items():
            if name in self.latency:
                self.latency[name] = float(value)
        self.objects_seen = int(reply.get("objects", 0))
        for t, kind, detail in reply.get("events", []):
            self.ctx.run.events.append(_event(t, kind, detail))
        return tuple(reply.get("command", (0.0, 0.0)))

    def _actors(self, hit_ids: np.ndarray) -> dict[str, dict]:
        out = {}
        for body in np.unique(hit_ids).tolist():
            gt = self.ctx.world.actor_by_body(body)
            if gt is not None:
                out[str(body)] = {"x": gt.x, "y": gt.y, "heading": gt.heading, "speed": gt.speed,
                                  "length_m": gt.length_m, "width_m": gt.width_m}
        return out

    def close(self) -> None:
        if getattr(self, "sock", None) is None:
            return
        try:
            send(self.sock, {"type": "bye"})
        except OSError:
            pass
        self.sock.close()
        self.sock = None


def _event(t, kind, detail):
    from addt_dsl.runtime.trace import Event

    return Event(float(t), str(kind), dict(detail))


def _jsonable(d: dict) -> dict:
    out = {}
    for k, v in d.items():
        if isinstance(v, np.generic):
            v = v.item()
        elif isinstance(v, np.ndarray):
            v = v.tolist()
        out[k] = v
    return out
