"""Calibrate the latency model on this host: `python -m addt_dsl.stack.calibrate`.

    python -m addt_dsl.stack.calibrate [--write] [--repeats 200] [--scans 240]
    python -m addt_dsl.stack.calibrate --show      # the shipped model's report, no timing

Method
1. Measure, on this host and on one thread, the compute time of each node of the default
   stack against the number of objects it handles: learned perception on generated scans
   (each scan a group, with the objects the lidar sees), the tracker updating N tracks
   with N detections, the lattice planner with N objects around the ego, the controller.
   Every call is kept: `--repeats` calls per object count (per scan for perception, a
   sixth of that), round-robin over the groups so load bursts hit all alike. Each call
   is timed twice: thread CPU time (the node's own compute, what the model uses) and
   wall time (which adds waits for the shared host's other processes; kept for the
   record as `wall_*`).
2. Trend per node: `base + per_object * N + per_object_sq * N²` through the CPU-time
   medians per group (base = the median with no objects, non-negative slopes by least
   squares through it; the quadratic term is the tracker's association).
3. Jitter per node: each call's CPU time divided by the median of its group, pooled over
   groups; the file keeps the quantiles of that ratio at `LEVELS`. Runs draw from them
   (`latency.LatencyModel.sample`).
4. With `--write`, store trend, jitter and the measurement conditions in
   `latency_model.json`. The file's `targets` (the factors to an embedded board) are
   inputs written by hand and kept as they are: nothing here fits them.
5. Print, for each target, the end-to-end latency against the object count (every node
   at its median; and the e2e p99 with each node drawing its own jitter, Monte Carlo with
   a fixed seed) and the object count at which each first exceeds 100 ms: a finding of
   the model, not a target of it.

The host is shared and loaded (its load average is recorded as `loadavg` in the file):
CPU time leaves out the waits for other processes, not their cache and memory
contention, so the jitter is this host's under that load, an upper bound on a quiet one's.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from addt_dsl import extras
from addt_dsl.stack.latency import MODEL_PATH, NODES, at, crossing, e2e_ms, e2e_quantile_ms, load_models, pipeline_ms
from addt_dsl.vehicles import CAR, DEFAULT_WHEELBASE_M

COUNTS = (0, 5, 10, 20, 40, 60, 100, 200, 400)  # the object counts the studies use
# Quantile levels of the jitter table; p99.9 is the last: above it a shared host's
# samples measure other processes' scheduling more than the node.
LEVELS = (0.0, 0.01, 0.05, 0.1, 0.25, 0.5, 0.75, 0.9, 0.95, 0.99, 0.995, 0.999)
LIMIT_MS, STEP_S = 100.0, 0.01  # the paper's budget; the suites' physics step
REPORT_COUNTS = (0, 10, 20, 40, 60, 80, 100, 200, 400)


def _timed(cases: list[tuple[int, object]], repeats: int) -> list[tuple[int, list[float], list[float]]]:
    """(objects, thread CPU times [s], wall times [s]) per case, `repeats` calls each after
    one untimed warm-up. Round-robin over the cases, so a burst of load on the shared host
    falls on every case alike instead of on one object count."""
    for _, fn in cases:
        fn()
    cpu: list[list[float]] = [[] for _ in cases]
    wall: list[list[float]] = [[] for _ in cases]
    for _ in range(repeats):
        for i, (_, fn) in enumerate(cases):
            w0, c0 = time.perf_counter(), time.thread_time()
            fn()
            c1, w1 = time.thread_time(), time.perf_counter()
            cpu[i].append(c1 - c0)
            wall[i].append(w1 - w0)
    return [(n, c, w) for (n, _), c, w in zip(cases, cpu, wall)]


def measure_perception(repeats: int, scans: int = 240) -> list[tuple[int, list[float], list[float]]]:
    """Per generated scan: visible objects and call times of learned perception's `detect`."""
    from addt_dsl.stack.learned import LearnedPerception
    from addt_dsl.stack.synth import generate

    node = LearnedPerception({})
    cases = [(int((s.hits >= 1).sum()), lambda s=s: node.detect(s.points, s.sensor_xy))
             for s in generate(scans, 424242)]
    return _timed(cases, max(3, repeats // 6))


def _objects(n: int, rng) -> list:
    from addt_dsl.stack.nodes import Obj

    return [Obj(float(rng.uniform(-60, 60)), float(rng.uniform(-8, 8)), 0.0, 20.0, 0.0, CAR.length_m, CAR.width_m)
            for _ in range(n)]


def measure_tracker(repeats: int) -> list[tuple[int, list[float], list[float]]]:
    from addt_dsl.stack.nodes import Tracker

    rng = np.random.default_rng(0)
    cases = []
    for n in COUNTS:
        objs = _objects(n, rng)

        def once(objs=objs):
            tr = Tracker()
            tr.tracks = [(o, 0.0, (0.01, 0.0, 0.01)) for o in objs]
            tr.update(objs, 0.1, lambda site, v: v)

        cases.append((n, once))
    return _timed(cases, repeats)


def _road():
    from addt_dsl.plan import RoadPlan, SegmentPlan
    from addt_dsl.runtime.fastroad import FastRoad
    from addt_dsl.road.roadspec import build_network

    plan = RoadPlan(name="r", source="inline", segments=[SegmentPlan(kind="line", length_m=1000.0)],
                    right_lanes=2)
    network = build_network([plan])["r"]
    return FastRoad(network.road(next(iter(network.roads))))


def measure_planner(repeats: int) -> list[tuple[int, list[float], list[float]]]:
    from addt_dsl.stack.nodes import LatticePlanner

    road = _road()
    rng = np.random.default_rng(1)
    lanes = road.driving_lane_ids(100.0)
    cases = []
    for n in COUNTS:
        objs = [(100.0 + float(rng.uniform(-60, 60)), float(road.lane_center_t(int(rng.choice(lanes)), 100.0)),
                 float(rng.uniform(10, 30)), 0.0, CAR.length_m, CAR.width_m) for _ in range(n)]
        lane0 = lanes[0]
        t0 = float(road.lane_center_t(lane0, 100.0))

        def once(objs=objs):
            LatticePlanner({}).plan((100.0, t0, lane0), 25.0, objs, road, "r", 0.0, lambda site, v: v)

        cases.append((n, once))
    return _timed(cases, repeats)


def measure_control(repeats: int) -> list[tuple[int, list[float], list[float]]]:
    from addt_dsl.stack.control import Controller
    from addt_dsl.stack.nodes import Plan

    road = _road()
    ctl = Controller({}, DEFAULT_WHEELBASE_M)
    t_lane = float(road.lane_center_t(-1, 100.0))
    plan = Plan(-1, t_lane, 25.0, 100.0, t_lane, 60.0, 0.0)
    x, y, h = road.reference_pose(100.0)
    # The controller's work does not depend on the object count: one group.
    return _timed([(0, lambda: ctl.command(plan, (x, y, h, 24.0), road, 100.0, t_lane, 0.01,
                                           lambda site, v: v))], repeats * len(COUNTS))


def fit(samples: list[tuple[float, float]]) -> tuple[float, float, float]:
    """Base [s], per-object [s] and per-object-pair [s] costs of `base + per * n + sq * n²`
    through (n, median) points.

    The base is the median cost with no objects (a free intercept can go negative); the
    two slopes are the least-squares ones through it, both kept non-negative (a negative
    one is dropped and the other refitted): the tracker's association is quadratic, the
    rest linear. Without zero-object samples, an ordinary line fit.
    """
    n = np.array([s[0] for s in samples], dtype=float)
    t = np.array([s[1] for s in samples], dtype=float)
    if np.ptp(n) == 0:
        return float(np.median(t)), 0.0, 0.0
    if not (n == 0).any():
        per, base = (float(v) for v in np.polyfit(n, t, 1))
        return max(base, 0.0), max(per, 0.0), 0.0
    base = float(np.median(t[n == 0]))
    y = t - base
    if len(np.unique(n)) >= 3:
        (per, sq), *_ = np.linalg.lstsq(np.column_stack([n, n * n]), y, rcond=None)
        if per >= 0 and sq >= 0:
            return base, float(per), float(sq)
        if per < 0 <= sq:
            return base, 0.0, max(float(np.sum(n * n * y) / np.sum(n ** 4)), 0.0)
    return base, max(float(np.sum(n * y) / np.sum(n * n)), 0.0), 0.0


def jitter(groups: list[tuple[int, list[float]]], levels=LEVELS) -> tuple[list[float], int]:
    """Quantiles at `levels` of each call's time over its group's median, pooled; and the
    number of calls."""
    ratios = np.concatenate([np.asarray(ts) / np.median(ts) for _, ts in groups])
    return [float(q) for q in np.quantile(ratios, levels)], int(ratios.size)


def node_entry(timed: list[tuple[int, list[float], list[float]]]) -> dict:
    """Trend and jitter from thread CPU times (the node's own compute); the wall-clock
    jitter, which adds the waits for the shared host's other processes, is kept for the
    record and not used."""
    cpu = [(n, c) for n, c, _ in timed]
    base, per, sq = fit([(n, float(np.median(ts))) for n, ts in cpu])
    ratios, count = jitter(cpu)
    wall = [(n, w) for n, _, w in timed]
    wall_base, wall_per, wall_sq = fit([(n, float(np.median(ts))) for n, ts in wall])
    return {"base_s": round(base, 9), "per_object_s": round(per, 10), "per_object_sq_s": round(sq, 13),
            "jitter_ratios": [round(r, 4) for r in ratios], "calls": count,
            "objects_measured": [min(n for n, *_ in timed), max(n for n, *_ in timed)],
            "wall_base_s": round(wall_base, 9), "wall_per_object_s": round(wall_per, 10),
            "wall_per_object_sq_s": round(wall_sq, 13),
            "wall_jitter_ratios": [round(r, 4) for r in jitter(wall)[0]]}


def calibrate(repeats: int, scans: int = 240, targets: dict | None = None) -> dict:
    """The model file's content: measured trend and jitter per node, `targets` as given
    (by default the current file's)."""
    import torch

    torch.set_num_threads(1)
    if targets is None:
        targets = json.loads(MODEL_PATH.read_text())["targets"]
    started = time.perf_counter()
    raw = {
        "perception": measure_perception(repeats, scans),
        "tracker": measure_tracker(repeats),
        "planner": measure_planner(repeats),
        "control": measure_control(repeats),
    }
    return {
        "about": ("Per-node latency model. `nodes` and `jitter_levels` are measured on the host named in "
                  "`calibration` (trend: medians per object count; jitter: quantiles of call time over its "
                  "group's median). `targets` are inputs, written by hand with their sources, never fitted. "
                  "Regenerate the measured part with `python -m addt_dsl.stack.calibrate --write`; see "
                  "docs/stack.md#latency."),
        "jitter_levels": list(LEVELS),
        "nodes": {node: node_entry(groups) for node, groups in raw.items()},
        "targets": targets,
        "calibration": {
            "method": "one thread; every call timed after one warm-up; trend through medians per object count "
                      "(base = median with no objects, least-squares slope through it); jitter = quantiles "
                      "of call / group median, pooled",
            "repeats": repeats,
            "scans": scans,
            "seconds": round(time.perf_counter() - started, 1),
            "loadavg": [round(v, 2) for v in os.getloadavg()],
            "cpus": os.cpu_count(),
            "date": datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%MZ"),
            "host": _host(),
        },
    }


def _host() -> str:
    import torch

    return f"{_cpu_name()}, Python {platform.python_version()}, torch {torch.__version__}"


def _cpu_name() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def report(model: dict, out=None) -> None:
    """Measured trend and jitter, then per target the e2e latency against object count
    and its first 100 ms crossing (all nodes at their medians, and the e2e p99 with each
    node drawing its own jitter)."""
    def say(*a):
        print(*a, file=out or sys.stdout)

    levels = model["jitter_levels"]
    say(f"{'node':<11} {'objects':>7} {'base ms':>9} {'per-obj us':>10} {'per-obj² ns':>11} {'calls':>6}  "
        "CPU-time ratio p01/p50/p90/p99/p99.9   (wall: base ms, per-obj us, p99, p99.9)")
    for node in NODES:
        v = model["nodes"][node]
        r = dict(zip(levels, v["jitter_ratios"]))
        w = dict(zip(levels, v["wall_jitter_ratios"]))
        lo, hi = v.get("objects_measured", ("?", "?"))
        say(f"{node:<11} {f'{lo}-{hi}':>7} {v['base_s'] * 1e3:>9.4f} {v['per_object_s'] * 1e6:>10.3f} "
            f"{v['per_object_sq_s'] * 1e9:>11.3f} {v['calls']:>6}  "
            f"{r[0.01]:.2f} / {r[0.5]:.2f} / {r[0.9]:.2f} / {r[0.99]:.2f} / {r[0.999]:.2f}"
            f"   ({v['wall_base_s'] * 1e3:.4f}, {v['wall_per_object_s'] * 1e6:.3f}, {w[0.99]:.2f}, {w[0.999]:.2f})")
    for name, t in model["targets"].items():
        models = load_models(name, data=model)
        say(f"target {name}: accelerator_scale {t['accelerator_scale']}, cpu_scale {t['cpu_scale']}")
        for n in REPORT_COUNTS:
            say(f"  {n:>3} objects: pipeline {pipeline_ms(at(models, n)):8.2f} ms, e2e median "
                f"{e2e_ms(at(models, n), STEP_S):8.2f} ms, e2e p99 {e2e_quantile_ms(models, n, 0.99, STEP_S):8.2f} ms")
        say(f"  e2e first over {LIMIT_MS:.0f} ms at {crossing(models, LIMIT_MS, STEP_S)} objects (median), "
            f"{crossing(models, LIMIT_MS, STEP_S, 0.99)} (e2e p99); step {STEP_S * 1e3:.0f} ms")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m addt_dsl.stack.calibrate", description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=200, help="timed calls per object count and node")
    ap.add_argument("--scans", type=int, default=240, help="generated lidar scans for perception")
    ap.add_argument("--write", action="store_true", help=f"write {MODEL_PATH.name}")
    ap.add_argument("--out", type=Path, default=MODEL_PATH)
    ap.add_argument("--show", type=Path, nargs="?", const=MODEL_PATH, default=None, metavar="FILE",
                    help="measure nothing: print the report of a stored model (default: the shipped one)")
    args = ap.parse_args(argv)
    if args.show is not None:
        report(json.loads(args.show.read_text()))
        return 0
    if (message := extras.missing_message("torch", "calibrating (it times learned perception)")) is not None:
        print(message, file=sys.stderr)
        return 2
    model = calibrate(args.repeats, args.scans)
    cal = model["calibration"]
    print(f"host {cal['host']}, load average {cal['loadavg']} on {cal['cpus']} CPUs, {cal['seconds']} s")
    report(model)
    if args.write:
        args.out.write_text(json.dumps(model, indent=2) + "\n")
        print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
