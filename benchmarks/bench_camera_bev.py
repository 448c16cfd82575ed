"""Cost per frame and real-time factor of `perception camera_bev` against the lidar modes.

    PYTHONPATH=. python benchmarks/bench_camera_bev.py [--repeats 3] [--duration 30]

Runs the overtake family (examples/suites/families/overtake*.addt, gap 40 m, no faults)
with ground-truth perception (its lidar), learned perception (the 5-channel lidar it is
trained for) and camera BEV perception (`families/overtake_camera_bev.addt`: the
six-camera rig), one process, one torch thread. Prints per configuration the real-time
factor (simulated time over wall time of `execute`, median of `--repeats` after a warm-up,
and over the process's CPU time, the steadier figure on a shared machine) and, for camera
BEV, the CPU time per frame of the rig's render (six TinyRenderer images) and of the
network (encoder, lift, BEV network, decoding). `uptime` before and after: the machine's
load is part of every figure.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import time

import _figures as figures_json
from bench_stack import timed

def _spec(perception: str, duration_s: float):
    from _families import family_spec

    if perception == "camera_bev":  # the family with the rig and `perception camera_bev` in it
        return family_spec("overtake_camera_bev", duration_s=duration_s, seed=7)
    return family_spec("overtake", perception, duration_s=duration_s, seed=7)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--duration", type=float, default=30.0, help="simulated seconds per run")
    ap.add_argument("--json", help="also write the figures here")
    args = ap.parse_args()

    import torch

    from addt_dsl.runtime import sensors
    from addt_dsl.runtime.execute import execute
    from addt_dsl.stack import camera_bev

    torch.set_num_threads(1)
    up = subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    print(f"overtake family, {args.duration:g} s simulated, no faults, torch threads 1 (uptime before: {up})")
    figures: dict = {"rtf": {}, "rtf_cpu": {}, "uptime_before": up}
    specs = {p: _spec(p, args.duration) for p in ("ground_truth", "learned", "camera_bev")}
    for spec in specs.values():
        execute(spec, keep_trace=False)  # warm-up: imports, weights, first-call costs
    walls = {p: [] for p in specs}
    cpus = {p: [] for p in specs}
    sim_s = {}
    for _ in range(args.repeats):  # interleaved: load changes hit every configuration alike
        for p, spec in specs.items():
            t0, c0 = time.perf_counter(), time.process_time()
            result = execute(spec, keep_trace=False)
            walls[p].append(time.perf_counter() - t0)
            cpus[p].append(time.process_time() - c0)
            sim_s[p] = result.sim_time_s
    for p in specs:
        wall, cpu = statistics.median(walls[p]), min(cpus[p])
        figures["rtf"][p], figures["rtf_cpu"][p] = sim_s[p] / wall, sim_s[p] / cpu
        print(f"  {p:<13} real-time factor {sim_s[p] / wall:>6.1f}x wall (median of {args.repeats}), "
              f"{sim_s[p] / cpu:>6.1f}x CPU (least); {sim_s[p]:.0f} s simulated")
    targets = [(sensors.CameraRig, "capture", "rig render (6 cameras)"),
               (camera_bev.CameraBevPerception, "run", "camera BEV perception"),
               (camera_bev.CameraBevPerception, "detect", "  network + decoding")]
    with timed(targets) as calls:
        execute(specs["camera_bev"], keep_trace=False)
    print(f"  {'camera_bev per frame (CPU time)':<34} {'frames':>6} {'ms/frame':>9}")
    figures["camera_bev_ms_per_frame"] = {}
    for _, _, label in targets:
        samples = calls.get(label, [])
        if samples:
            ms = 1e3 * statistics.median(samples)
            figures["camera_bev_ms_per_frame"][label.strip()] = ms
            print(f"  {label:<34} {len(samples):>6} {ms:>9.2f}")
    up_after = subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
    figures["uptime_after"] = up_after
    print(f"(uptime after: {up_after})")
    figures_json.write(args.json, figures)


if __name__ == "__main__":
    main()
