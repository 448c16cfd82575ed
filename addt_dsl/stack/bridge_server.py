"""Reference bridge server: hosts the default `bev` stack for `stack external` runs.

    python -m addt_dsl.stack.bridge_server [--address 127.0.0.1:5555]

Prints `listening HOST:PORT` once it accepts connections (`--address 127.0.0.1:0` picks a
free port). Each connection is one run: `hello` builds a `BevStack` from the settings
and the map it carries, every `step` replays the step's frames into it and ticks it,
`bye` ends the run. Connections are served one thread each, so parallel runs may share a
server. It is also the worked example of the protocol in docs/bridge.md: a stack in any
language needs only to answer these three messages.
"""

from __future__ import annotations

import argparse
import socket
import socketserver
import sys
import threading
import zlib
from collections.abc import Mapping
from types import MappingProxyType

import numpy as np

from addt_dsl.stack.bridge import PROTOCOL, parse_address, recv, send


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


class _Frame:
    def __init__(self, sensor: str, stamp_s: float, data: dict):
        self.sensor, self.stamp_s, self.data = sensor, stamp_s, data


class _GT:
    def __init__(self, d: dict):
        self.x, self.y, self.heading, self.speed = d["x"], d["y"], d["heading"], d["speed"]
        self.length_m, self.width_m = d["length_m"], d["width_m"]


class _NoFaults:
    """The remote side has no fault schedule (faults act in the simulator's process)."""

    by_target: Mapping[str, list] = MappingProxyType({})

    def for_target(self, target: str) -> list:
        return []


class _RemoteContext:
    """What `BevStack` asks of the simulator, answered from the bridge messages."""

    def __init__(self, hello: dict):
        from addt_dsl.plan import RoadPlan
        from addt_dsl.runtime.fastroad import FastRoad
        from addt_dsl.runtime.roadspec import build_network

        road_plan = RoadPlan.model_validate(hello["map"]["road"])
        network = build_network([road_plan])[road_plan.name]
        road_id = road_plan.xodr_road_id if road_plan.source == "xodr" and road_plan.xodr_road_id \
            else next(iter(network.roads))
        self.road = FastRoad(network.road(road_id))
        self.road_id = road_id
        self.seed = int(hello["seed"])
        self.wheelbase_m = float(hello["ego"]["wheelbase_m"])
        self.ego_lane = int(hello["ego"]["lane"])
        self.sensors = {d["name"]: _Sensor(d) for d in hello["sensors"]}
        self.faults = _NoFaults()
        self.now = 0.0
        self.ego = (0.0, 0.0, 0.0, 0.0)
        self.ego_s = 0.0
        self.actors: dict[int, _GT] = {}
        self.events: list = []
        self.commands: list = []
        self.run = self  # BevStack reads ctx.run.ego_s
        self.world = self  # ... and passes ctx.world to perception (actor_by_body)

    # The same derivation as the in-process context, so a remote run matches a local one.
    def rng(self, name: str) -> np.random.Generator:
        return np.random.default_rng([self.seed, zlib.crc32(b"stack"), zlib.crc32(name.encode())])

    def ego_pose(self):
        return self.ego

    def ego_road(self):
        return self.road, self.road_id

    def sensor(self, name: str):
        return self.sensors[name]

    def actor_by_body(self, body: int):
        return self.actors.get(body)

    def event(self, kind: str, **detail) -> None:
        self.events.append([self.now, kind, detail])

    def apply_command_at(self, time_s: float, steer: float, accel: float) -> None:
        self.commands.append([time_s, steer, accel])


def serve_connection(sock: socket.socket) -> None:
    """Run one bridge session on a connected socket until `bye` or the peer closes."""
    from addt_dsl.stack.bev import BevStack

    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    stack = ctx = None
    while True:
        try:
            header, blobs = recv(sock)
        except ConnectionError:
            return
        kind = header.get("type")
        try:
            if kind == "hello":
                if header.get("protocol") != PROTOCOL:
                    raise ValueError(f"protocol {header.get('protocol')} not supported (this is {PROTOCOL})")
                ctx = _RemoteContext(header)
                stack = BevStack(header["stack"], ctx)
                send(sock, {"type": "ready", "stack": "bev", "nodes": list(stack.latency)})
            elif kind == "step":
                if stack is None:
                    raise ValueError("step before hello")
                send(sock, _step(stack, ctx, header, blobs))
            elif kind == "bye":
                return
            else:
                raise ValueError(f"unknown message type {kind!r}")
        except Exception as exc:  # noqa: BLE001 - reported to the simulator, which marks the run
            send(sock, {"type": "error", "message": f"{type(exc).__name__}: {exc}"})
            return


def _step(stack, ctx: _RemoteContext, header: dict, blobs: dict) -> dict:
    t = float(header["time_s"])
    ctx.now = t
    e = header["ego"]
    ctx.ego = (e["x"], e["y"], e["heading"], e["speed"])
    ctx.ego_s = e["s_hint"]
    ctx.events, ctx.commands = [], []
    for f in header["frames"]:
        if "points" in f:
            truth = f.get("truth", {})
            hit = blobs[truth["hit_body"]] if "hit_body" in truth else np.zeros(0, dtype=np.int64)
            data = {"points": blobs[f["points"]], "hit_body": hit}
            sensor = ctx.sensors[f["sensor"]]
            sensor.actual = _Extrinsics(truth["actual"]) if "actual" in truth else sensor.nominal
            ctx.actors = {int(k): _GT(v) for k, v in truth.get("actors", {}).items()}
        else:
            data = dict(f.get("values", {}))
            data.update({key: blobs[name] for key, name in f.get("arrays", {}).items()})
        stack.on_frame(_Frame(f["sensor"], f["stamp_s"], data), f["arrive_s"])
    command = stack.step(t, float(header["dt"]))
    return {"type": "control", "command": list(command), "commands": ctx.commands,
            "latency": dict(stack.latency), "objects": stack.objects_seen, "events": ctx.events}


class _Handler(socketserver.BaseRequestHandler):
    def handle(self):
        serve_connection(self.request)


class BridgeServer(socketserver.ThreadingTCPServer):
    daemon_threads = True
    allow_reuse_address = True

    def __init__(self, address: str):
        super().__init__(parse_address(address), _Handler)

    @property
    def address(self) -> str:
        host, port = self.server_address[:2]
        return f"{host}:{port}"


def start_in_thread(address: str = "127.0.0.1:0") -> BridgeServer:
    """A server on a background thread (for tests and notebooks); `shutdown()` it when done."""
    server = BridgeServer(address)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m addt_dsl.stack.bridge_server", description=__doc__.split("\n")[0])
    ap.add_argument("--address", default="127.0.0.1:5555", help="HOST:PORT to listen on (port 0: any free one)")
    args = ap.parse_args(argv)
    with BridgeServer(args.address) as server:
        print(f"listening {server.address}", flush=True)
        try:
            server.serve_forever()
        except KeyboardInterrupt:
            pass
    return 0


if __name__ == "__main__":
    sys.exit(main())
