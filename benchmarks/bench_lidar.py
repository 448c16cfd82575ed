"""Cost of one lidar frame (`Lidar.capture` over a `PhysicsWorld` of boxes on flat ground: the
analytic ray caster and its glue), in two checkouts back to back.

Each configuration is a lidar (RAYSxCHANNELS, 12 deg vertical field, 80 m range, on the
default mount 1 m up inside the ego's box, as the paper families' lidar) among N cars posed
at random 8-40 m away (seeded), the ego ignored as the loop's `ray_cast` ignores it. A child process per checkout (its
PYTHONPATH the checkout), alternating checkouts, `--repeat` times; in each, the least of 5
rounds of `--frames` captures, each from another ego pose. The digest of the frames'
points and bodies shows both checkouts see the same scans.

Run: PYTHONPATH=. python benchmarks/bench_lidar.py [--checkouts OTHER_CHECKOUT,.] [--cars 1,5,20]
     [--lidars 360x5,1024x16] [--frames 400] [--repeat 3] [--json FILE]
Prints us per frame per checkout, the ratio first/last, and the load.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import _figures as figures_json


def arg(name: str, default: str) -> str:
    return sys.argv[sys.argv.index(name) + 1] if name in sys.argv else default


class _World:
    """What a lidar reads of the loop's world (`views.SensorWorld`): the ego's frame and ray casts."""

    def __init__(self, physics, frame):
        self.physics, self.frame = physics, frame

    def ego_frame(self):
        return self.frame

    def ego_pose(self):
        x, y, _, heading, _ = self.frame
        return x, y, heading, 0.0

    def ray_cast(self, starts, ends):
        return self.physics.ray_cast(starts, ends, ignore="ego")


def child(lidar_spec: str, cars: int, frames: int) -> dict:
    """In a checkout: least us per frame, and the digest of every frame's points and bodies."""
    import hashlib
    import math

    import numpy as np

    from addt_dsl.runtime.sensors import Lidar
    from addt_dsl.runtime.world import PhysicsWorld

    rays, channels = (int(x) for x in lidar_spec.split("x"))
    lidar = Lidar("lidar", {"rays": rays, "channels": channels, "vfov": math.radians(12.0), "range": 80.0})
    rng = np.random.default_rng(20261207)
    physics = PhysicsWorld()
    physics.add_box("ego", 4.6, 1.9, 1.5)
    physics.set_pose("ego", 0.0, 0.0, 0.75, 0.0)
    for k in range(cars):
        physics.add_box(f"car{k}", 4.6, 1.9, 1.5)
        r, a = rng.uniform(8.0, 40.0), rng.uniform(-math.pi, math.pi)
        physics.set_pose(f"car{k}", r * math.cos(a), r * math.sin(a), 0.75, rng.uniform(-0.3, 0.3))
    poses = [(float(x), float(y), 0.0, float(h), 0.0) for x, y, h in
             zip(rng.uniform(-0.5, 0.5, frames), rng.uniform(-0.3, 0.3, frames), rng.uniform(-0.05, 0.05, frames))]
    worlds = [_World(physics, p) for p in poses]

    def scan(world):  # the loop poses the ego, then the lidar looks
        physics.set_pose("ego", world.frame[0], world.frame[1], 0.75, world.frame[3])
        return lidar.capture(world, 0.0)

    digest, points = hashlib.sha256(), 0
    for world in worlds:  # (compiles the kernels; the digest of the scans)
        frame = scan(world)
        points += len(frame.data["points"])
        digest.update(np.ascontiguousarray(frame.data["points"]).tobytes())
        digest.update(np.asarray(frame.data["hit_body"], dtype=np.int64).tobytes())
    best = math.inf
    clock = time.perf_counter
    for _ in range(5):
        t0 = clock()
        for world in worlds:
            scan(world)
        best = min(best, (clock() - t0) / frames)
    physics.close()
    return {"us_per_frame": 1e6 * best, "digest": digest.hexdigest()[:16], "points": points}


def main() -> None:
    if "--child" in sys.argv:
        lidar_spec, cars, frames = arg("--child", "").split(",")
        print(json.dumps(child(lidar_spec, int(cars), int(frames))))
        return
    checkouts = [str(Path(p).resolve()) for p in arg("--checkouts", ".").split(",")]
    repeat, frames = int(arg("--repeat", "3")), int(arg("--frames", "400"))
    figures: dict = {"checkouts": checkouts}
    print(f"load average before: {', '.join(f'{x:.2f}' for x in os.getloadavg())} on {os.cpu_count()} CPUs")
    print("checkouts: " + "  ".join(f"[{i}] {c}" for i, c in enumerate(checkouts)))
    print(f"us per lidar frame (Lidar.capture, perf_counter, least of 5 rounds of {frames} frames, "
          f"least of {repeat} processes)")
    print(f"{'lidar':>8s} {'cars':>5s} " + " ".join(f"{'[' + str(i) + ']':>9s}" for i in range(len(checkouts)))
          + "  ratio [0]/[-1]  digests  points/frame  load")
    for lidar_spec in arg("--lidars", "360x5,1024x16").split(","):
        for cars in (int(x) for x in arg("--cars", "1,5,20").split(",")):
            rows: list[list[dict]] = [[] for _ in checkouts]
            for _ in range(repeat):
                for i, checkout in enumerate(checkouts):
                    env = {**os.environ, "PYTHONPATH": checkout}
                    out = subprocess.run([sys.executable, __file__, "--child", f"{lidar_spec},{cars},{frames}"],
                                         env=env, capture_output=True, text=True, check=True).stdout
                    rows[i].append(json.loads(out.strip().splitlines()[-1]))
            us = [min(r["us_per_frame"] for r in runs) for runs in rows]
            digests = {r["digest"] for runs in rows for r in runs}
            load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
            print(f"{lidar_spec:>8s} {cars:5d} " + " ".join(f"{u:9.1f}" for u in us)
                  + f"  {us[0] / us[-1]:13.2f}x  {'equal' if len(digests) == 1 else 'DIFFER':>7s}"
                  + f"  {rows[0][0]['points'] / frames:12.0f}  {load}", flush=True)
            figures[f"{lidar_spec}/{cars}"] = {"us_per_frame": us, "digests_equal": len(digests) == 1,
                                               "load": figures_json.load()}
    figures_json.write(arg("--json", "") or None, figures)


if __name__ == "__main__":
    main()
