"""Helpers for fault unit tests: build one fault kind as the runtime would, feed it frames."""

from __future__ import annotations

import numpy as np

from addt_dsl.plan import ConcreteFault
from addt_dsl.runtime.faults import Binding, FaultSchedule
from addt_dsl.runtime.sensors import Frame

STEP_S = 0.01


def schedule(*faults: dict, duration_s: float = 10.0):
    """A FaultSchedule from dicts like {"kind": "drop", "target": "lidar", "rate": 0.5}."""
    concrete = []
    for i, spec in enumerate(faults):
        spec = dict(spec)
        kind, target = spec.pop("kind"), spec.pop("target", "lidar")
        start, end, seed = spec.pop("start", 0.0), spec.pop("end", None), spec.pop("seed", 1 + i)
        concrete.append(ConcreteFault(index=i, kind=kind, target=target, start_s=start, end_s=end,
                                      settings=spec, seed=seed))
    events: list = []
    return FaultSchedule(concrete, STEP_S, duration_s, events), events


def one(kind: str, **settings):
    """(the fault kind instance, its event list)."""
    sched, events = schedule({"kind": kind, **settings})
    return sched.kinds[0], events


def bound(kind: str, nodes=None, tensor_sites=None, clock=lambda: 0.0, **settings):
    sched, events = schedule({"kind": kind, **settings})
    stack = type("Stack", (), {})()
    stack.nodes = nodes or {}
    if tensor_sites is not None:
        stack.tensor_sites = lambda: tensor_sites
    sched.bind(stack, clock)
    return sched, sched.kinds[0], events


def lidar_frame(n: int = 200, stamp: float = 0.0, seed: int = 0) -> Frame:
    rng = np.random.default_rng(seed)
    az = rng.uniform(-np.pi, np.pi, n)
    r = rng.uniform(5.0, 60.0, n)
    pts = np.stack([r * np.cos(az), r * np.sin(az), np.zeros(n)], axis=1)
    return Frame("lidar", stamp, {"points": pts, "hit_body": rng.integers(1, 5, n)})


def camera_frame(h: int = 48, w: int = 64, dtype=np.uint8, stamp: float = 0.0) -> Frame:
    """A checkerboard with a gradient: sharp edges in both directions, values across the range."""
    yy, xx = np.mgrid[0:h, 0:w]
    board = (((yy // 8) + (xx // 8)) % 2).astype(np.float64)
    img = 0.2 + 0.6 * board[..., None] * np.array([1.0, 0.8, 0.6]) + 0.1 * (xx / w)[..., None]
    img = np.clip(img, 0, 1)
    if np.issubdtype(dtype, np.integer):
        img = np.rint(img * 255).astype(dtype)
    else:
        img = img.astype(dtype)
    return Frame("camera", stamp, {"image": img})


def binding(**kw) -> Binding:
    return Binding(**kw)
