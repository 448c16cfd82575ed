"""Rough per-call cost of the road queries used in the simulation loop and oracles.

Run: PYTHONPATH=. python benchmarks/bench_road.py
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _figures as figures_json  # noqa: E402

from addt_dsl.road import load_xodr  # noqa: E402

DATA = Path(__file__).resolve().parents[1] / "tests" / "data" / "xodr"


def per_call(fn, n):
    fn()
    t0 = time.perf_counter()
    for _ in range(n):
        fn()
    return (time.perf_counter() - t0) / n


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--json", help="also write the figures here")
    args = ap.parse_args()
    rng = np.random.default_rng(1)
    figures = {}
    for name in ("straight_500m.xodr", "curves_elevation.xodr", "jolengatan.xodr"):
        net = load_xodr(DATA / name)
        road = next(iter(net.roads.values()))
        s = rng.uniform(0.0, road.length, 10_000)
        x, y, _ = road.lane_center(-1, s)
        x = x + rng.normal(0.0, 1.0, x.shape)
        y = y + rng.normal(0.0, 1.0, y.shape)
        i = iter(range(10**9))
        t_center = per_call(lambda: net.lane_center(road.id, -1, float(s[next(i) % 10_000])), 2000)
        t_coords = per_call(lambda: net.to_road_coords(float(x[next(i) % 10_000]), float(y[next(i) % 10_000])), 300)
        t_center_v = per_call(lambda: road.lane_center(-1, s), 20) / s.size
        t_coords_v = per_call(lambda: net.to_road_coords_array(x, y), 3) / s.size
        t_offset_v = per_call(lambda: road.lane_offset(-1, x, y), 3) / s.size
        figures[name] = {"lane_center_us": t_center * 1e6, "lane_center_vectorised_us_per_point": t_center_v * 1e6,
                          "to_road_coords_us": t_coords * 1e6,
                          "to_road_coords_vectorised_us_per_point": t_coords_v * 1e6,
                          "lane_offset_vectorised_us_per_point": t_offset_v * 1e6}
        print(
            f"{name:24s} ({len(road.geometries):2d} geometries, {len(road._sample_s):4d} samples): "
            f"lane_center {t_center * 1e6:6.1f} us/call, {t_center_v * 1e6:5.2f} us/pt vectorised; "
            f"to_road_coords {t_coords * 1e6:6.1f} us/call, {t_coords_v * 1e6:5.2f} us/pt vectorised; "
            f"lane_offset {t_offset_v * 1e6:5.2f} us/pt vectorised"
        )
    figures_json.write(args.json, figures)


if __name__ == "__main__":
    main()
