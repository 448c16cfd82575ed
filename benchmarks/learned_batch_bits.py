"""Whether the learned detector's layers give the same bits for windows convolved together
(a batch of several runs' windows, or one window padded to a shared shape) as for each
window alone, as the detector convolves them (`learned.RegionForward`, batch 1).

Run: PYTHONPATH=. python benchmarks/learned_batch_bits.py [--trials N] [--json F]

For each named layer of the shipped weights, random windows (ReLU'd and signed values) of
4x4 and 8x8 output cells: (a) the windows of N runs stacked into one batch (N = 2, 7, 16,
64) against each alone; (b) one window inside a larger one (the cells it shares: what
padding every run's window to the batch's largest shape computes). It prints, per layer,
in how many trials every element had the same bits; a learned run may be stepped with
others' windows only where both say all. One intra-op thread, the oneDNN ISA cap the
detector sets (`learned.py`): the machine's own kernels decide, so run it where it counts.
"""

from __future__ import annotations

import os
import random
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import _figures as figures_json  # noqa: E402

TRIALS = int(sys.argv[sys.argv.index("--trials") + 1]) if "--trials" in sys.argv else 10
JSON_PATH = sys.argv[sys.argv.index("--json") + 1] if "--json" in sys.argv else None
BATCHES = (2, 7, 16, 64)


def _same(a, b) -> bool:
    import torch

    return a.shape == b.shape and torch.equal(a.contiguous().view(torch.int32), b.contiguous().view(torch.int32))


def main() -> None:
    import torch
    import torch.nn.functional as F

    from addt_dsl.stack import learned

    torch.set_num_threads(1)
    model, _ = learned.load_model()
    rng = random.Random(0)
    torch.manual_seed(0)
    figures: dict[str, dict] = {}
    print(f"load average {', '.join(f'{x:.2f}' for x in os.getloadavg())}; oneDNN ISA cap "
          f"{os.environ.get('ONEDNN_MAX_CPU_ISA')}; {TRIALS} trials per cell: trials with every bit the same")
    print(f"{'layer':20s} " + " ".join(f"{'batch ' + str(n):>9s}" for n in BATCHES) + f" {'padded':>9s}")
    with torch.inference_mode():
        for name, layer in model.layers().items():
            k, s, cin = layer.kernel_size[0], layer.stride[0], layer.in_channels
            same = dict.fromkeys(BATCHES, 0)
            padded = 0
            for trial in range(TRIALS):
                cells = 4 if trial % 2 == 0 else 8
                win = (cells - 1) * s + k
                x = torch.randn(max(BATCHES), cin, win, win)
                if trial % 3 == 0:
                    x = torch.relu(x)
                alone = torch.cat([F.conv2d(x[i:i + 1], layer.weight, layer.bias, s) for i in range(max(BATCHES))])
                for n in BATCHES:
                    same[n] += _same(F.conv2d(x[:n], layer.weight, layer.bias, s), alone[:n])
                # the window at an offset of whole strides inside one (2..6 strides) larger
                grow_r, grow_c = rng.randint(1, 3), rng.randint(1, 3)
                rows, cols = win + s * (grow_r + rng.randint(1, 3)), win + s * (grow_c + rng.randint(1, 3))
                big = torch.randn(1, cin, rows, cols)
                big[:, :, s * grow_r:s * grow_r + win, s * grow_c:s * grow_c + win] = x[:1]
                out = F.conv2d(big, layer.weight, layer.bias, s)
                padded += _same(out[:, :, grow_r:grow_r + cells, grow_c:grow_c + cells], alone[:1])
            figures[name] = {**{f"batch_{n}": same[n] for n in BATCHES}, "padded": padded, "trials": TRIALS}
            cells_out = " ".join(f"{same[n]:>6d}/{TRIALS:<2d}" for n in BATCHES)
            print(f"{name:20s} {cells_out} {padded:>6d}/{TRIALS:<2d}", flush=True)
    figures_json.write(JSON_PATH, {"layers": figures, "isa_cap": os.environ.get("ONEDNN_MAX_CPU_ISA")})


if __name__ == "__main__":
    main()
