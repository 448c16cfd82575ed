"""Overhead of each fault kind per run, against the fault-free run (target: under 5 %).

Closed-loop kinds run in the vehicle-following scenario (20 s simulated, one lidar at 10 Hz),
each fault active for the whole run with mild settings; runs are interleaved round-robin and
the least CPU time of `--repeat` is compared, which filters out noise from other processes.
`none (again)` is the fault-free run measured a second time: its "overhead" is the noise floor.
Camera kinds (blur, image_noise, occlude) are measured per frame and compared with the
cost of rendering that frame, the camera's own cost (the scenario perceives from lidar).
Tensor bit flips: the cost of the armed hooks per inference of the detector network.

Run: PYTHONPATH=. python benchmarks/bench_faults.py [--repeat 7] [--kinds random_value,stuck]
"""

from __future__ import annotations

import argparse
import json
import time
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


# getCameraImage (ER_TINY_RENDERER) per frame, from ../shared/design/PERFORMANCE.md: what a
# camera already costs per frame, against which a corruption's cost is compared.
RENDER_S = {(240, 320): 0.012, (480, 640): 0.048}


def camera_kinds(repeat: int) -> dict[tuple[str, tuple[int, int]], float]:
    """Seconds per uint8 frame for each camera corruption, at 320x240 and 640x480."""
    from addt_dsl.plan import ConcreteFault
    from addt_dsl.runtime.faults import FaultSchedule
    from addt_dsl.runtime.sensors import Frame

    settings = {"blur": {"sigma": 2.0}, "image_noise": {"sigma": 8.0}, "occlude": {"fraction": 0.2}}
    rng = np.random.default_rng(0)
    out = {}
    for shape in RENDER_S:
        img = rng.integers(0, 256, (*shape, 3), dtype=np.uint8)
        for kind, st in settings.items():
            sched = FaultSchedule([ConcreteFault(index=0, kind=kind, target="camera", start_s=0.0, end_s=None,
                                                 settings=st, seed=1)], 0.01, 100.0, [])
            fault = sched.kinds[0]
            fault.on_frame(Frame("camera", 0.0, {"image": img}), 0.0)
            t = []
            for _ in range(repeat * 5):
                t0 = time.perf_counter()
                fault.on_frame(Frame("camera", 0.0, {"image": img}), 0.0)
                t.append(time.perf_counter() - t0)
            out[(kind, shape)] = min(t)
    return out


def tensor_hooks(repeat: int) -> dict[str, float]:
    """Seconds per inference of a small CNN: clean, with an armed weight fault, with an armed
    activation fault (the hooks run every inference; the flips themselves are rare)."""
    import torch

    from addt_dsl.runtime.faults.base import Binding
    from addt_dsl.runtime.faults.compute import BitFlip
    from addt_dsl.runtime.faults.tensor import tensor_sites_of

    class _F:
        index, kind, start_s, end_s, seed = 0, "bitflip", 1e9, None, 1

    torch.set_num_threads(1)
    model = torch.nn.Sequential(torch.nn.Conv2d(3, 16, 3, padding=1), torch.nn.ReLU(),
                                torch.nn.Conv2d(16, 16, 3, padding=1), torch.nn.ReLU(),
                                torch.nn.AdaptiveAvgPool2d(1), torch.nn.Flatten(), torch.nn.Linear(16, 4)).eval()
    x = torch.randn(1, 3, 64, 64)

    def per_inference():
        with torch.no_grad():
            for _ in range(5):
                model(x)
            t = []
            for _ in range(repeat * 20):
                t0 = time.perf_counter()
                model(x)
                t.append(time.perf_counter() - t0)
        return min(t)

    out = {"clean": per_inference()}
    for mode in ("weights", "activations"):
        f = _F()
        f.target, f.settings = "perception_2", {"tensor": mode, "count": 3}
        kind = BitFlip(f, 0.01, 1e9, lambda t, d: None)
        kind.bind(Binding(tensor_sites=tensor_sites_of(model, "perception"), clock=lambda: 0.0))
        out[mode] = per_inference()
        kind.close()
    return out


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeat", type=int, default=9)
    parser.add_argument("--json", help="also write the figures here")
    parser.add_argument("--kinds", help="comma-separated closed-loop kinds only (the fault-free runs "
                                        "always run; camera and tensor figures are skipped)")
    args = parser.parse_args()
    kinds = set(args.kinds.split(",")) if args.kinds else None

    best, events = closed_loop(args.repeat, kinds)
    base = best["none"]
    figures = {"run_wall_s": base, "simulated_s": DURATION_S, "overhead": {}}
    print(f"fault-free run: {base * 1000:.0f} ms CPU for {DURATION_S:g} s simulated "
          f"(least of {args.repeat})")
    print(f"{'kind':14s} {'CPU ms':>8s} {'overhead':>9s} {'events':>7s}")
    for k, t in best.items():
        if k == "none":
            continue
        over = t / base - 1.0
        figures["overhead"][k] = over
        print(f"{k:14s} {t * 1000:8.0f} {over * 100:8.1f}% {events[k]:7d}")
    if kinds is not None:
        if args.json:
            Path(args.json).write_text(json.dumps(figures, indent=2) + "\n")
        return
    for (k, shape), t in camera_kinds(args.repeat).items():
        over = t / RENDER_S[shape]
        figures["overhead"][f"{k} {shape[1]}x{shape[0]}"] = over
        print(f"{k:14s} {shape[1]}x{shape[0]}: {t * 1e3:6.2f} ms/frame = {over * 100:5.1f}% of rendering the frame")
    try:
        hooks = tensor_hooks(args.repeat)
    except ImportError:
        hooks = None
    if hooks:
        for mode in ("weights", "activations"):
            over = hooks[mode] / hooks["clean"] - 1.0
            figures["overhead"][f"bitflip tensor {mode}"] = over
            print(f"bitflip tensor {mode:11s}: {hooks[mode] * 1e6:6.0f} us/inference vs {hooks['clean'] * 1e6:.0f} "
                  f"clean -> {over * 100:5.1f}% of the model's time (armed hook, no flip due)")
    if args.json:
        Path(args.json).write_text(json.dumps(figures, indent=2) + "\n")


if __name__ == "__main__":
    main()
