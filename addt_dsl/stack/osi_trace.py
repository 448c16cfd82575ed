"""A run's ground truth as an ASAM OSI trace (`addtc trace DIR RUN_ID --osi FILE`).

One `osi3.SensorView` per recorded sample (its `global_ground_truth`: every actor, the
ego as the host; `host_vehicle_data`: the ego), in the mapping of `osi_mapping`. The
lanes of the ego's road network go in the first message only (static ground truth, as
esmini writes it). Written as

- `.osi`: OSI's single-channel binary trace, each message preceded by its length as a
  little-endian uint32 (what `osi3trace.OSITrace` reads);
- `.mcap`: one channel `ground_truth` of `osi3.SensorView` with the file metadata
  `net.asam.osi.trace` that OSI's multi-channel format asks for.

What the trace does not record is not invented: z is half the body height above z = 0
(road heights are not in the trace), velocity and acceleration lie along the heading.
"""

from __future__ import annotations

import math
import struct
from pathlib import Path

from addt_dsl.stack import osi_mapping as M

FORMATS = (".osi", ".mcap")


def views(spec, trace):
    """The SensorViews of a run, one per sample (a generator)."""
    from osi3.osi_sensorview_pb2 import SensorView

    plan = spec.plan
    from addt_dsl.vehicles import VEHICLES

    actors = {"ego": plan.ego, **{a.name: a for a in plan.agents}}
    height = {name: a.height_m or VEHICLES[a.vehicle].height_m for name, a in actors.items()}
    kind = {"ego": "ego", **{a.name: a.vehicle for a in plan.agents}}
    names = list(trace.actors)
    ids = {name: M.HOST_ID + k for k, name in enumerate(names)}  # ego first: the live protocol's ids
    static = SensorView()
    static.global_ground_truth.CopyFrom(M.lanes_ground_truth(*_lanes(plan)))
    for k, t in enumerate(trace.time):
        objects = []
        for name in names:
            a = trace.actors[name]
            h, v, acc = float(a.heading[k]), float(a.speed[k]), float(a.accel[k])
            c, s = math.cos(h), math.sin(h)
            objects.append(M.ObjectState(ids[name], kind[name], float(a.x[k]), float(a.y[k]), 0.5 * height[name], h,
                                         v * c, v * s, a.length_m, a.width_m, height[name], acc * c, acc * s,
                                         float(a.yaw_rate[k])))
        view = M.WorldView(float(t), objects[0], objects[1:])
        sv = M.sensor_view(view, objects[0], float(t))
        if k == 0:
            sv.MergeFrom(static)
        yield sv


def _lanes(plan):
    from addt_dsl.road.roadspec import build_network

    network = build_network(plan.roads)[plan.ego.road]
    return M.sample_lanes([network.road(rid) for rid in sorted(network.roads)])


def write(spec, trace, path: str | Path) -> int:
    """Write the trace to `path` (.osi or .mcap); returns the number of messages."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in FORMATS:
        raise ValueError(f"an OSI trace is written as {' or '.join(FORMATS)}, not {path.suffix or 'no suffix'!r}")
    path.parent.mkdir(parents=True, exist_ok=True)
    n = 0
    if suffix == ".osi":
        with open(path, "wb") as f:
            for sv in views(spec, trace):
                data = sv.SerializeToString()
                f.write(struct.pack("<I", len(data)) + data)
                n += 1
        return n
    from mcap_protobuf.writer import Writer

    version = ".".join(map(str, M.OSI_VERSION))
    with open(path, "wb") as f, Writer(f) as w:
        w.add_metadata("net.asam.osi.trace", {"version": version, "min_osi_version": version,
                                              "max_osi_version": version, "description":
                                              f"addt-dsl run of scenario {spec.plan.name}"})
        for sv in views(spec, trace):
            ns = sv.timestamp.seconds * 1_000_000_000 + sv.timestamp.nanos
            w.write_message("ground_truth", sv, log_time=ns, publish_time=ns)
            n += 1
    return n
