"""Learned-perception throughput by batch size and device, and a CUDA bit-flip check.

    python benchmarks/bench_perception_gpu.py [--device cuda] [--batches 1 16 256 1024]

Torch only (no pybullet), so it runs on an accelerator machine. Prints inferences per
second for the detector network (grid → heatmap and boxes, no decoding) at each batch
size in fp32 (and bf16 autocast on CUDA), and checks that `tensorfaults.flip_bits` gives
the same bits on the device as on the CPU, for weights and for a transient activation.
"""

from __future__ import annotations

import argparse
import time

import _figures as figures_json
import torch

from addt_dsl.stack.bev_grid import GRID
from addt_dsl.stack.learned import BevDetector, load_model
from addt_dsl.stack.tensorfaults import ActivationFlip, flip_bits


def throughput(model, device: str, batch: int, dtype=None, seconds: float = 1.0) -> float:
    x = torch.zeros((batch, *GRID.shape), device=device)
    x[:, :, ::7, ::5] = 1.0  # a sparse grid like a real scan's

    def once():
        with torch.inference_mode():
            if dtype is not None:
                with torch.autocast(device_type="cuda", dtype=dtype):
                    model(x)
            else:
                model(x)

    for _ in range(5):
        once()
    sync = torch.cuda.synchronize if device.startswith("cuda") else (lambda: None)
    sync()
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        once()
        n += 1
    sync()
    return n * batch / (time.perf_counter() - t0)


def check_flips(device: str) -> None:
    torch.manual_seed(0)
    values = torch.randn(1000)
    idx = torch.randint(0, 1000, (64,)).tolist()
    bits = torch.randint(0, 32, (64,)).tolist()
    cpu, dev = values.clone(), values.clone().to(device)
    flip_bits(cpu, idx, bits)
    flip_bits(dev, idx, bits)
    same = torch.equal(cpu.view(torch.int32), dev.cpu().view(torch.int32))
    print(f"weight-style flips on {device} match cpu bit for bit: {same}")
    assert same
    model = BevDetector().to(device).eval()
    x = torch.zeros((1, *GRID.shape), device=device)
    x[:, :, ::7, ::5] = 1.0
    with torch.inference_mode():
        clean = model(x)[0].clone()
    layer = model.layers()["backbone.conv2"]
    with ActivationFlip(layer, [123], [30]) as flip, torch.inference_mode():
        faulty = model(x)[0].clone()
    with torch.inference_mode():
        after = model(x)[0].clone()
    print(f"activation flip on {device}: {flip.fired}, output changed: {not torch.equal(clean, faulty)}, "
          f"next inference clean: {torch.equal(clean, after)}")
    assert not torch.equal(clean, faulty) and torch.equal(clean, after)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    ap.add_argument("--batches", type=int, nargs="*", default=[1, 16, 256, 1024])
    ap.add_argument("--json", help="also write the figures here")
    args = ap.parse_args()
    torch.set_num_threads(1)
    model, _ = load_model(device=args.device)
    name = torch.cuda.get_device_name() if args.device.startswith("cuda") else "cpu, 1 thread"
    print(f"device: {name}; torch {torch.__version__}")
    figures = {"device": name, "inferences_per_s": {}}
    for batch in args.batches:
        fp32 = throughput(model, args.device, batch)
        figures["inferences_per_s"][f"batch {batch} fp32"] = fp32
        line = f"batch {batch:>5}: fp32 {fp32:>10.0f} inferences/s"
        if args.device.startswith("cuda"):
            bf16 = throughput(model, args.device, batch, torch.bfloat16)
            figures["inferences_per_s"][f"batch {batch} bf16"] = bf16
            line += f", bf16 autocast {bf16:>10.0f}/s"
        print(line)
    if args.device.startswith("cuda"):
        check_flips(args.device)
        figures["cuda_flips_match_cpu"] = True  # check_flips asserts it
    figures_json.write(args.json, figures)


if __name__ == "__main__":
    main()
