"""Overhead of each fault kind per run, against the fault-free run (target: under 5 %).

Closed-loop kinds run in the vehicle-following scenario (20 s simulated, one lidar at 10 Hz),
each fault active for the whole run with mild settings; runs are interleaved round-robin and
the least CPU time of `--repeat` is compared, which filters out noise from other processes.
`none (again)` is the fault-free run measured a second time: its "overhead" is the noise floor.
Camera kinds (blur, image_noise, occlude) are measured per frame and compared with the
cost of rendering that frame, the camera's own cost, measured in the same run in a posed
twin world: a `camera` at 320x240 and 640x480, and the six 128x40 images of a
`camera_rig` (`perception camera_bev`'s rig).
Tensor bit flips, on the shipped detector in the learned `following` family (20 s, a lidar
frame every 0.1 s): (a) a fault whose window is the last second against the fault-free run
(hooks attach only at a flip's instant, so this is ~1.0), with the previous method beside it
(hooks attached all run, maps cloned and compared every inference); (b) the cost inside a
window, as a window over the whole run with 1 flip a second and with 10 (one per lidar frame
on average). A flipped activation far from the points widens the changed region that the
following layers compute (the flip's effect is computed, not skipped): that, not the hook,
is most of (b). (c) The same per flip, replayed on the detector alone over that run's lidar
frames (steadier than whole-run ratios on a loaded machine): the added inference time, the
XOR itself, and the empty-grid rebuild after a weight flip.

Run: PYTHONPATH=. python benchmarks/bench_faults.py [--repeat 7] [--kinds random_value,stuck]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from contextlib import contextmanager, nullcontext
from pathlib import Path

import numpy as np

from addt_dsl.compiler import compile_source
from addt_dsl.runtime.execute import execute
from addt_dsl.sweep import expand

SUITES = Path(__file__).resolve().parents[1] / "examples" / "suites"
DURATION_S = 20.0

CLOSED_LOOP = {
    "none": "",
    "none (again)": "",  # the noise floor: the same fault-free run measured as if it were a kind
    "drop": "drop lidar rate 10 %",
    "delay": "delay lidar by 30 ms jitter 20 ms",
    "skew": "skew lidar by -20 ms",
    "shift": "shift lidar yaw 2 deg ramp 5 s",
    "noise": "noise lidar range 5 cm dropout 10 %",
    "bitflip": "during [1 s, 19 s] bitflip control count 5 field mantissa",
    "stuck": "stuck control.integral value 0.5",
    "random_value": "random_value control.steer low -0.001 high 0.001",
    "spike": "spike planner by 20 ms",
    "slow": "slow perception factor 1.5",
}


def spec_with(fault: str):
    src = (f"scenario bench {{\n  duration {DURATION_S} s\n  seed 1\n"
           f'  include "families/following.addt"\n'
           + (f"  faults {{\n    {fault}\n  }}\n" if fault else "") + "}\n")
    result = compile_source(src, "bench.addt", base_dir=SUITES)
    assert result.ok, result.diagnostics
    return expand(result.plan).specs[0]


def closed_loop(repeat: int, kinds=None) -> tuple[dict[str, float], dict[str, int]]:
    chosen = {k: v for k, v in CLOSED_LOOP.items() if kinds is None or k in kinds or not v}
    specs = {k: spec_with(v) for k, v in chosen.items()}
    for s in specs.values():  # warm-up: imports, caches
        execute(s, keep_trace=False)
    best = {k: float("inf") for k in specs}
    events = {}
    for _ in range(repeat):
        for k, s in specs.items():
            t0 = time.process_time()  # CPU time: steadier than wall time on a shared machine
            r = execute(s, keep_trace=False)
            best[k] = min(best[k], time.process_time() - t0)
            events[k] = r.fault_events
    return best, events


CAMERA_SHAPES = ((240, 320), (480, 640))  # (H, W) of a `camera` frame
RIG = "sensor camera_rig rate 10 Hz cameras 6 width 128 height 40 fov 64 deg"  # perception camera_bev's rig


def render_s() -> dict[tuple, float]:
    """CPU seconds per frame of rendering what the corruptions act on, measured here in a
    posed twin world (5 agents, TinyRenderer; bench_twin.sensor_ms): a `camera` (its
    default, segmentation on) at each of CAMERA_SHAPES, and the six-camera rig
    (key "rig"). A corruption's cost is compared with these."""
    from bench_twin import sensor_ms

    out = {shape: sensor_ms(f"sensor camera rate 10 Hz width {shape[1]} height {shape[0]}", repeat=3)[0] / 1e3
           for shape in CAMERA_SHAPES}
    out["rig"] = sensor_ms(RIG, repeat=3)[0] / 1e3
    return out


def _best(fn, repeat: int) -> float:
    fn()
    t = []
    for _ in range(repeat * 5):
        t0 = time.perf_counter()
        fn()
        t.append(time.perf_counter() - t0)
    return min(t)


def camera_kinds(repeat: int) -> dict[tuple[str, object], float]:
    """Seconds per uint8 frame for each camera corruption, at 320x240 and 640x480, and on
    the six images (6 x 40 x 128) of a `camera_rig` frame (key "rig")."""
    from addt_dsl.plan import ConcreteFault
    from addt_dsl.runtime.faults import FaultSchedule
    from addt_dsl.runtime.sensors import Frame

    settings = {"blur": {"sigma": 2.0}, "image_noise": {"sigma": 8.0}, "occlude": {"fraction": 0.2}}
    rng = np.random.default_rng(0)
    out = {}
    for shape in (*CAMERA_SHAPES, "rig"):
        target = "camera_rig" if shape == "rig" else "camera"
        key = "images" if shape == "rig" else "image"
        img = rng.integers(0, 256, (6, 40, 128, 3) if shape == "rig" else (*shape, 3), dtype=np.uint8)
        for kind, st in settings.items():
            sched = FaultSchedule([ConcreteFault(index=0, kind=kind, target=target, start_s=0.0, end_s=None,
                                                 settings=st, seed=1)], 0.01, 100.0, [])
            fault = sched.kinds[0]
            out[(kind, shape)] = _best(lambda: fault.on_frame(Frame(target, 0.0, {key: img}), 0.0), repeat)
    return out


TENSOR_SITE = "perception.backbone.conv0"  # the largest output map (32 x 76 x 32): the costliest to clone
TENSOR_FAMILY = "following"
TENSOR_RUNS = {
    # label: (fault lines, run with the previous method)
    "none": ("", False),
    "none (again)": ("", False),
    "activations, last second": (f"during [{DURATION_S - 1:g} s, {DURATION_S:g} s] bitflip {TENSOR_SITE} "
                                 "tensor activations", False),
    "weights, last second": (f"during [{DURATION_S - 1:g} s, {DURATION_S:g} s] bitflip {TENSOR_SITE} "
                             "tensor weights", False),
    "activations, last second, previous method": (
        f"during [{DURATION_S - 1:g} s, {DURATION_S:g} s] bitflip {TENSOR_SITE} tensor activations", True),
    # Inside a window: the window is the whole run, 1 flip a second, then 10 (one per lidar frame on average).
    "activations, whole run, 1 flip/s": (f"bitflip {TENSOR_SITE} tensor activations count {int(DURATION_S)}",
                                         False),
    "activations, whole run, 1 flip/s, previous method": (
        f"bitflip {TENSOR_SITE} tensor activations count {int(DURATION_S)}", True),
    "activations, whole run, 10 flips/s": (f"bitflip {TENSOR_SITE} tensor activations count {int(DURATION_S * 10)}",
                                           False),
    "weights, whole run, 1 flip/s": (f"bitflip {TENSOR_SITE} tensor weights count {int(DURATION_S)}", False),
}


@contextmanager
def previous_method():
    """The tensor fault hooks as they were: attached for the whole run (timers fire at
    once) and taken by the detector's RegionForward by cloning and comparing the map."""
    from addt_dsl.runtime.faults.base import FaultSchedule
    from addt_dsl.runtime.faults.tensor import TensorFlipper

    at, owned = FaultSchedule.at, TensorFlipper.flip_owned
    FaultSchedule.at = lambda self, time_s, callback: callback()
    TensorFlipper.flip_owned = None
    try:
        yield
    finally:
        FaultSchedule.at, TensorFlipper.flip_owned = at, owned


def tensor_faults(repeat: int) -> tuple[dict[str, float], dict[str, int]]:
    """CPU seconds per run of the learned `following` family (the shipped detector) with a
    tensor fault on its first layer: window in the last second, with the previous method,
    and a window over the whole run with a flip per lidar frame on average."""
    import torch

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from _families import family_spec

    torch.set_num_threads(1)
    specs = {k: (family_spec(TENSOR_FAMILY, "learned", DURATION_S, fault, seed=1), old)
             for k, (fault, old) in TENSOR_RUNS.items()}

    def run(spec, old):
        with previous_method() if old else nullcontext():
            return execute(spec, keep_trace=False)

    for spec, old in specs.values():  # warm-up: imports, weights, caches
        run(spec, old)
    best = {k: float("inf") for k in specs}
    events = {}
    for _ in range(repeat):
        for k, (spec, old) in specs.items():
            t0 = time.process_time()
            r = run(spec, old)
            best[k] = min(best[k], time.process_time() - t0)
            events[k] = r.fault_events
    return best, events


def tensor_flip_costs(repeat: int) -> dict[str, float]:
    """CPU microseconds a tensor flip adds, replayed on the detector alone: the lidar frames
    of the learned `TENSOR_FAMILY` run go through `LearnedPerception.detect` (least of
    `repeat` passes), without flips and with one flip in `TENSOR_SITE`'s output per frame
    (element and bit uniform); the XOR itself (`flip_bit_`); the rebuild of the empty-grid
    maps after a weight flip of the site (mantissa bits), and recomputing every map as before."""
    import torch

    from addt_dsl.runtime.faults.tensor import flip_bit_
    from addt_dsl.stack import learned

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from _families import family_spec

    torch.set_num_threads(1)
    frames = []
    build = learned.build_grid_region

    def capture(points, sensor_xy, **kwargs):
        frames.append((points.copy(), sensor_xy))
        return build(points, sensor_xy, **kwargs)

    learned.build_grid_region = capture
    try:
        execute(family_spec(TENSOR_FAMILY, "learned", DURATION_S, seed=1), keep_trace=False)
    finally:
        learned.build_grid_region = build
    node = learned.LearnedPerception({})
    rng = np.random.default_rng(0)
    numel = node.site_numel(TENSOR_SITE, "activations")
    picks = [(int(rng.integers(numel)), int(rng.integers(32))) for _ in frames]

    def per_frame(flip: bool) -> float:
        best = float("inf")
        for _ in range(repeat):
            t = 0.0
            for (points, sensor_xy), (k, bit) in zip(frames, picks, strict=True):
                if flip:
                    node.flip_activation_bits(TENSOR_SITE, [k], [bit])
                t0 = time.thread_time()
                node.detect(points, sensor_xy)
                t += time.thread_time() - t0
            best = min(best, t / len(frames))
        return best

    out = {"frames": len(frames), "detect_us": 1e6 * per_frame(False), "detect_flipped_us": 1e6 * per_frame(True)}
    buf = torch.zeros(1, 32, 76, 32)
    t0 = time.thread_time()
    for k, bit in picks:
        flip_bit_(buf, k, bit)
    out["flip_us"] = 1e6 * (time.thread_time() - t0) / len(picks)
    # Weight flips as the fault's pre-hook leaves them: in place, then the maps rebuilt.
    forward, layer = node._forward, node._layer(TENSOR_SITE)
    n_w = layer.weight.numel() + layer.bias.numel()
    for label, full in (("rebuild_us", False), ("full_rebuild_us", True)):
        times = []
        with torch.inference_mode():
            for _ in range(10 * repeat):
                k = int(rng.integers(n_w))
                flip_bit_(layer.weight.data if k < layer.weight.numel() else layer.bias.data,
                          k % layer.weight.numel() if k < layer.weight.numel() else k - layer.weight.numel(),
                          int(rng.integers(23)))  # mantissa bits: the network stays finite
                if full:
                    forward._last_backgrounds = {}  # every map recomputed, as before
                t0 = time.thread_time()
                forward._rebuild()
                times.append(time.thread_time() - t0)
        out[label] = 1e6 * float(np.median(times))
    return out


def closed_loop_and_camera(args, kinds, figures: dict) -> None:
    best, events = closed_loop(args.repeat, kinds)
    base = best["none"]
    figures.update(run_wall_s=base, simulated_s=DURATION_S)
    print(f"fault-free run: {base * 1000:.0f} ms CPU for {DURATION_S:g} s simulated "
          f"(least of {args.repeat}; uptime: {uptime()})")
    print(f"{'kind':14s} {'CPU ms':>8s} {'overhead':>9s} {'events':>7s}")
    for k, t in best.items():
        if k == "none":
            continue
        over = t / base - 1.0
        figures["overhead"][k] = over
        print(f"{k:14s} {t * 1000:8.0f} {over * 100:8.1f}% {events[k]:7d}")
    if kinds is not None:
        return
    render = render_s()
    figures["render_ms_per_frame"] = {("rig 6x128x40" if k == "rig" else f"{k[1]}x{k[0]}"): v * 1e3
                                      for k, v in render.items()}
    print("rendering, measured here (CPU ms per frame): " +
          ", ".join(f"{name} {ms:.2f}" for name, ms in figures["render_ms_per_frame"].items()))
    for (k, shape), t in camera_kinds(args.repeat).items():
        over = t / render[shape]
        name = "rig 6x128x40" if shape == "rig" else f"{shape[1]}x{shape[0]}"
        figures["overhead"][f"{k} {name}"] = over
        print(f"{k:14s} {name}: {t * 1e3:6.2f} ms/frame = {over * 100:5.1f}% of rendering the frame")


def uptime() -> str:
    """`uptime` beside the figures: the machine is shared, a figure needs its load."""
    try:
        return subprocess.run(["uptime"], capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        import os

        return "load average: " + ", ".join(f"{x:.2f}" for x in os.getloadavg())


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeat", type=int, default=9)
    parser.add_argument("--json", help="also write the figures here")
    parser.add_argument("--kinds", help="comma-separated closed-loop kinds only (the fault-free runs "
                                        "always run; camera and tensor figures are skipped)")
    parser.add_argument("--tensor-only", action="store_true", help="only the tensor fault figures")
    args = parser.parse_args()
    kinds = set(args.kinds.split(",")) if args.kinds else None
    figures = {"overhead": {}}
    if not args.tensor_only:
        closed_loop_and_camera(args, kinds, figures)
        if kinds is not None:
            if args.json:
                Path(args.json).write_text(json.dumps(figures, indent=2) + "\n")
            return

    try:
        import torch  # noqa: F401
    except ImportError:
        print("tensor faults: skipped (torch is not installed)")
    else:
        best, events = tensor_faults(args.repeat)
        base = best["none"]
        print(f"\ntensor bit flips on the shipped detector ({TENSOR_SITE}), learned {TENSOR_FAMILY} family, "
              f"{DURATION_S:g} s simulated: fault-free {base * 1000:.0f} ms CPU = "
              f"{DURATION_S / base:.0f}x real time (least of {args.repeat}; uptime: {uptime()})")
        print(f"{'fault':52s} {'CPU ms':>8s} {'ratio':>7s} {'flips':>6s}")
        tensor = figures["tensor"] = {"family": TENSOR_FAMILY, "site": TENSOR_SITE, "cpu_s": best,
                                      "flips": events, "ratio": {}}
        for k, t in best.items():
            tensor["ratio"][k] = t / base
            if k != "none":
                figures["overhead"][f"bitflip tensor {k}"] = t / base - 1.0
                print(f"{k:52s} {t * 1000:8.0f} {t / base:7.3f} {events[k]:6d}")
        costs = tensor["per_flip"] = tensor_flip_costs(args.repeat)
        per_sim_s_us = 1e6 * base / DURATION_S
        print(f"\nper flip, replayed on the detector alone ({costs['frames']} lidar frames of that run; "
              f"uptime: {uptime()}):\n"
              f"  detect {costs['detect_us']:.0f} us a frame; with a flip in {TENSOR_SITE}'s output every frame "
              f"{costs['detect_flipped_us']:.0f} us (+{costs['detect_flipped_us'] - costs['detect_us']:.0f} us: the "
              f"widened region), of which the flip itself {costs['flip_us']:.1f} us\n"
              f"  = {100 * (costs['detect_flipped_us'] - costs['detect_us']) / per_sim_s_us:.1f} % of the fault-free "
              f"run per flip a second\n"
              f"  weight flip: empty-grid maps rebuilt in {costs['rebuild_us']:.0f} us "
              f"(recomputing every map: {costs['full_rebuild_us']:.0f} us), median")
    if args.json:
        Path(args.json).write_text(json.dumps(figures, indent=2) + "\n")


if __name__ == "__main__":
    main()
