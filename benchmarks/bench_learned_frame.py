"""Per lidar frame cost of the learned detector's Python around the CNN: `bev_grid.decode`
(peaks, boxes, the overlap test) and the cluster class reader (`cluster_features`,
`TreeEnsemble.logits`) of this checkout, and of another's with `--base` (e.g. a worktree of an older commit), on the
frames of dense-traffic runs with learned perception (1/5/20/50 agents).

Run: PYTHONPATH=. python benchmarks/bench_learned_frame.py [--base /path/to/checkout] [--seconds S] [--json F]

Records each frame's decode and reclass inputs (head maps; returns, sensor, boxes) from one
run per agent count, then times both versions over the same frames back to back (least of
several repeats), and checks they give the same bits.
"""

from __future__ import annotations

import importlib.util
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_dense import dense_source, spec_of  # noqa: E402

import _figures as figures_json  # noqa: E402

BASE = Path(sys.argv[sys.argv.index("--base") + 1]) if "--base" in sys.argv else None  # None: this checkout alone
JSON_PATH = sys.argv[sys.argv.index("--json") + 1] if "--json" in sys.argv else None
SECONDS = float(sys.argv[sys.argv.index("--seconds") + 1]) if "--seconds" in sys.argv else 3.0


def record(n_agents: int) -> tuple[list[tuple], list[tuple]]:
    """(reclass inputs, decode inputs) of each frame of one run."""
    from addt_dsl.runtime.execute import execute
    from addt_dsl.stack import cluster_class, learned

    frames, maps, reclass, decode = [], [], cluster_class.reclass, learned.decode

    def keep(boxes, points, sensor_xy, box_map, ensemble, offsets=None):
        frames.append((np.array(points), tuple(sensor_xy), boxes.copy(), box_map.copy()))
        return reclass(boxes, points, sensor_xy, box_map, ensemble, offsets)

    def keep_maps(heat, box, threshold):
        maps.append((heat.copy(), box.copy(), threshold))
        return decode(heat, box, threshold)

    cluster_class.reclass, learned.decode = keep, keep_maps
    try:
        execute(spec_of(dense_source(n_agents, "learned", SECONDS)), keep_trace=False)
    finally:
        cluster_class.reclass, learned.decode = reclass, decode
    return frames, maps


def per_frame_us(fn, frames, repeat: int = 5) -> float:
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        for f in frames:
            fn(f)
        best = min(best, time.perf_counter() - t0)
    return best / len(frames) * 1e6


def _load(name: str):
    """Module `addt_dsl.stack.<name>` of the base checkout, under another name."""
    spec = importlib.util.spec_from_file_location(f"base_{name}", BASE / f"addt_dsl/stack/{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # (dataclasses look their module up)
    spec.loader.exec_module(module)
    return module


def main() -> None:
    import torch

    torch.set_num_threads(1)
    from addt_dsl.stack import cluster_class as new
    from addt_dsl.stack.learned import load_cluster_classes

    from addt_dsl.stack import bev_grid

    ensemble, _ = load_cluster_classes()
    if BASE is None:  # this checkout alone: its figures in the "now" columns, base = now
        old, old_grid, old_ensemble = new, bev_grid, ensemble
    else:
        old, old_grid = (_load(name) for name in ("cluster_class", "bev_grid"))
        old_ensemble = old.TreeEnsemble.from_state(ensemble.state())
    load = os.getloadavg()
    figures: dict = {"base": str(BASE) if BASE else None, "load_average": load, "per_frame_us": {}}
    print(f"learned detector's Python per lidar frame: {BASE or 'this checkout'} (base) vs this checkout; load average "
          f"{load[0]:.2f} {load[1]:.2f} {load[2]:.2f} on {os.cpu_count()} cores")
    print(f"  {'agents':>6s} {'frames':>6s} {'dets/frame':>10s}  {'decode base':>11s} {'now':>7s} {'x':>5s}"
          f"  {'features base':>13s} {'now':>7s} {'x':>5s}  {'logits base':>11s} {'now':>7s} {'x':>5s}")
    for n in (1, 5, 20, 50):
        frames, maps = record(n)
        frames = [f for f in frames if len(f[2])]
        for m in maps:
            assert np.array_equal(old_grid.decode(*m).view(np.int64), bev_grid.decode(*m).view(np.int64))
        dc_old = per_frame_us(lambda m: old_grid.decode(*m), maps)
        dc_new = per_frame_us(lambda m: bev_grid.decode(*m), maps)
        feats = [new.cluster_features(*f) for f in frames]
        inputs = [fv[0][fv[1]] for fv in feats]
        for f, (fn, vn), x in zip(frames, feats, inputs):  # same bits
            fo, vo = old.cluster_features(*f)
            assert np.array_equal(vo, vn) and np.array_equal(fo.view(np.int64), fn.view(np.int64))
            assert np.array_equal(old_ensemble.logits(x).view(np.int64), ensemble.logits(x).view(np.int64))
        cf_old = per_frame_us(lambda f: old.cluster_features(*f), frames)
        cf_new = per_frame_us(lambda f: new.cluster_features(*f), frames)
        lg_old = per_frame_us(old_ensemble.logits, inputs)
        lg_new = per_frame_us(ensemble.logits, inputs)
        dets = np.mean([len(f[2]) for f in frames])
        print(f"  {n:6d} {len(frames):6d} {dets:10.1f}  {dc_old:9.0f}us {dc_new:5.0f}us {dc_old / dc_new:5.1f}"
              f"  {cf_old:11.0f}us {cf_new:5.0f}us {cf_old / cf_new:5.1f}"
              f"  {lg_old:9.0f}us {lg_new:5.0f}us {lg_old / lg_new:5.1f}", flush=True)
        figures["per_frame_us"][n] = {"frames": len(frames), "detections_per_frame": float(dets),
                                      "decode": [dc_old, dc_new], "features": [cf_old, cf_new],
                                      "logits": [lg_old, lg_new]}
    figures_json.write(JSON_PATH, figures)


if __name__ == "__main__":
    main()
