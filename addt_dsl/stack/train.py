"""Train the BEV detector on scans generated from the twin: `python -m addt_dsl.stack.train`.

    python -m addt_dsl.stack.train --seed 0 --out addt_dsl/stack/perception_weights.pt

Generates `--scenes` labelled scans with `synth.ScanGenerator` (the runtime's `Lidar` in
a pybullet world of car and truck boxes), then trains `learned.BevDetector` with Adam on
a CenterNet loss (focal loss on the centre heatmap; L1 at object centres on the sub-cell
offset, weighted 2, on log length/width and on the box axis as sin 2θ, cos 2θ; cross
entropy at object centres on the class, car / truck / pedestrian / cyclist, optionally
weighted per class with `--class-weights`). Objects with at least one lidar return are
positives. `--init WEIGHTS` fine-tunes from a weights file instead of starting afresh
(its layer widths are used); `--cyclists MEAN` puts more cyclists in the scenes than
the held-out evaluation set has. `--cluster-scenes N` then fits the class reader on
each detection's cluster of returns (`cluster_class`) to the trained detector's
detections on N fresh scans (the default scenes) and ships it in the same file.

Reproducible from the seed: the scenes, the initial weights and the batch order all
derive from it, and training runs on `--threads` CPU threads (default 2; the same
seed and thread count give the same weights, bit for bit, on the same machine).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

from addt_dsl import extras
from addt_dsl.stack.bev_grid import BOX_CHANNELS, CLASSES, DETECTOR_LIDAR, GRID, build_grid, encode_targets
from addt_dsl.stack.synth import CYCLISTS_PER_SCENE, generate, in_grid, load_samples, save_samples


def make_targets(samples):
    """Stacked CenterNet targets for `samples` (objects with ≥ 1 return are positives)."""
    hx, hy = GRID.head_shape
    heat = np.zeros((len(samples), hx, hy), dtype=np.float32)
    reg = np.zeros((len(samples), BOX_CHANNELS + 1, hx, hy), dtype=np.float32)
    mask = np.zeros((len(samples), hx, hy), dtype=np.float32)
    for k, s in enumerate(samples):
        keep = in_grid(s.boxes) & (s.hits >= 1)
        heat[k], reg[k], mask[k] = encode_targets(s.boxes[keep], classes=s.classes[keep])
    return heat, reg, mask


def grids(samples, out: np.ndarray) -> np.ndarray:
    for k, s in enumerate(samples):
        build_grid(s.points, s.sensor_xy, out=out[k])
    return out[: len(samples)]


def centernet_loss(heat_logits, box, heat_t, reg_t, mask_t, class_weight=None):
    """The loss and its parts; `class_weight` (a tensor, one weight per class) scales
    each object's class cross entropy by its true class's weight."""
    import torch
    import torch.nn.functional as F

    logits = heat_logits[:, 0]
    p = torch.sigmoid(logits).clamp(1e-4, 1 - 1e-4)
    pos = heat_t.eq(1.0).float()
    n_pos = pos.sum().clamp(min=1.0)
    log_p = F.logsigmoid(logits)
    log_1mp = F.logsigmoid(-logits)
    pos_loss = (log_p * (1 - p) ** 2 * pos).sum()
    neg_loss = (log_1mp * p ** 2 * (1 - heat_t) ** 4 * (1 - pos)).sum()
    focal = -(pos_loss + neg_loss) / n_pos
    m = mask_t[:, None]
    l1 = (box[:, :BOX_CHANNELS] - reg_t[:, :BOX_CHANNELS]).abs() * m
    offset = l1[:, 0:2].sum() / n_pos
    size = l1[:, 2:4].sum() / n_pos
    heading = l1[:, 4:6].sum() / n_pos
    # Class: cross entropy over the logits at the object centres.
    target = reg_t[:, BOX_CHANNELS].long()
    ce = F.cross_entropy(box[:, BOX_CHANNELS:], target, reduction="none")
    if class_weight is not None:
        ce = ce * class_weight[target]
    cls = (ce * mask_t).sum() / n_pos
    return (focal + 2.0 * offset + size + heading + cls,
            (focal.item(), offset.item(), size.item(), heading.item(), cls.item()))


def train(seed: int, scenes: int, epochs: int, batch: int, threads: int, lr: float, log=print,
          cache: Path | None = None, device: str = "cpu", widths: tuple[int, int, int] = (32, 48, 64),
          lidars: tuple[str, ...] = (DETECTOR_LIDAR.config,), lidar_p: tuple[float, ...] | None = None,
          lidar_settings: dict | None = None, init: Path | None = None,
          class_weights: tuple[float, ...] | None = None, cyclists: float = CYCLISTS_PER_SCENE,
          logit_offsets: tuple[float, ...] | None = None):
    """A trained detector and its timings; `init`: weights file to start from (fine-tuning;
    `epochs` 0 with `init`: no scans, no training), `class_weights`: per-class weights of the
    class loss, `cyclists`: see `synth.sample_scene`; `logit_offsets`: added to the class
    logits' biases after training (logit adjustment: data with more of a class than the
    scenes the detector meets make it guess that class too readily)."""
    import torch

    from addt_dsl.stack.learned import BevDetector

    torch.set_num_threads(threads)
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    if epochs == 0 and init is not None:
        model = _initial_model(init, device)
        _offset_logits(model, logit_offsets)
        return model.cpu().eval(), {"generate_s": 0.0, "train_s": 0.0}
    t0 = time.perf_counter()
    if cache is not None and cache.exists():
        samples = load_samples(cache)[:scenes]
        scenes = len(samples)
    else:
        samples = generate(scenes, seed, lidars=lidars, lidar_p=lidar_p, lidar_settings=lidar_settings,
                           cyclists=cyclists)
        if cache is not None:
            save_samples(cache, samples)
    heat_all, reg_all, mask_all = make_targets(samples)
    t_gen = time.perf_counter() - t0
    seen = np.bincount(np.concatenate([s.classes[s.hits >= 1] for s in samples]), minlength=len(CLASSES))
    log(f"generated {scenes} scans in {t_gen:.1f} s "
        f"({np.mean([len(s.points) for s in samples]):.0f} points, "
        f"{np.mean([(s.hits >= 1).sum() for s in samples]):.1f} visible objects per scan; "
        + ", ".join(f"{n} {c}" for c, n in zip(CLASSES, seen.tolist())) + ")")

    model = _initial_model(init, device) if init is not None else BevDetector(widths).to(device)
    weight = None if class_weights is None else torch.tensor(class_weights, dtype=torch.float32, device=device)
    buf = np.zeros((batch, *GRID.shape), dtype=np.float32)

    def forward(idx):
        x = torch.from_numpy(grids([samples[i] for i in idx], buf).copy()).to(device)
        heat_logits, box = model(x)
        return heat_logits, box, (torch.from_numpy(a[idx]).to(device) for a in (heat_all, reg_all, mask_all))

    t_train = fit(model, lr, scenes, batch, epochs, rng, forward, log, class_weight=weight)
    _offset_logits(model, logit_offsets)
    return model.cpu().eval(), {"generate_s": round(t_gen, 1), "train_s": round(t_train, 1)}


def _initial_model(init: Path, device: str):
    from addt_dsl.stack.learned import load_model

    model, _ = load_model(init)
    model.widen_input()  # weights from before the grid's range and count channels: zero weights for them
    return model.to(device)


def _offset_logits(model, offsets: tuple[float, ...] | None) -> None:
    import torch

    if offsets is not None:
        with torch.no_grad():
            bias = model.head["box"].bias
            bias[BOX_CHANNELS:] += torch.tensor(offsets, dtype=bias.dtype, device=bias.device)


def fit(model, lr: float, scenes: int, batch: int, epochs: int, rng, forward, log=print,
        class_weight=None) -> float:
    """The training loop of both detectors (this one and `camera_train`'s): AdamW with a
    one-cycle schedule on the CenterNet loss, scenes in a fresh order from `rng` every
    epoch; `forward(idx)` gives (heat logits, box, targets) for a batch's scene indices.
    `class_weight`: see `centernet_loss`. Returns the training time [s]."""
    import torch

    opt = torch.optim.AdamW(model.parameters(), lr=lr, weight_decay=1e-4)
    steps = epochs * math.ceil(scenes / batch)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=lr, total_steps=steps, pct_start=0.15)
    t1 = time.perf_counter()
    for epoch in range(epochs):
        order = rng.permutation(scenes)
        totals = np.zeros(6)
        model.train()
        for start in range(0, scenes, batch):
            heat_logits, box, targets = forward(order[start:start + batch])
            loss, parts = centernet_loss(heat_logits, box, *targets, class_weight=class_weight)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            sched.step()
            totals += (loss.item(), *parts)
        n = math.ceil(scenes / batch)
        log(f"epoch {epoch + 1}/{epochs}: loss {totals[0] / n:.3f} (focal {totals[1] / n:.3f}, "
            f"offset {totals[2] / n:.3f}, size {totals[3] / n:.3f}, heading {totals[4] / n:.3f}, "
            f"class {totals[5] / n:.3f}) [{time.perf_counter() - t1:.0f} s]")
    return time.perf_counter() - t1


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m addt_dsl.stack.train", description=__doc__.split("\n")[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=Path(__file__).with_name("perception_weights.pt"))
    ap.add_argument("--scenes", type=int, default=16000, help="training scans to generate")
    ap.add_argument("--epochs", type=int, default=16)
    ap.add_argument("--batch", type=int, default=32)
    ap.add_argument("--lr", type=float, default=3e-3)
    ap.add_argument("--threads", type=int, default=2, help="CPU threads (reproducible per thread count)")
    ap.add_argument("--threshold", type=float, default=0.35, help="detection threshold stored with the weights")
    ap.add_argument("--cache", type=Path, default=None, help="npz of scans: reused if present, else written")
    ap.add_argument("--widths", type=int, nargs=3, default=[32, 48, 64], help="channels at 1/2, 1/4, 1/8")
    ap.add_argument("--lidars", nargs="*", default=[DETECTOR_LIDAR.config],
                    help="RAYSxCHANNELS configurations to scan with (default: bev_grid.DETECTOR_LIDAR)")
    ap.add_argument("--lidar-p", type=float, nargs="*", default=None, help="their probabilities (default: equal)")
    ap.add_argument("--lidar-vfov", type=float, default=DETECTOR_LIDAR.vfov_deg, metavar="DEG",
                    help="vertical field of view of multi-channel lidars")
    ap.add_argument("--device", default="cpu", help="torch device (the shipped weights are trained on cpu)")
    ap.add_argument("--init", type=Path, default=None, metavar="WEIGHTS",
                    help="fine-tune from this weights file (its widths replace --widths)")
    ap.add_argument("--class-weights", type=float, nargs=len(CLASSES), default=None, metavar="W",
                    help="weights of the class loss per class (" + ", ".join(CLASSES) + "; default: all 1)")
    ap.add_argument("--class-logit-offsets", type=float, nargs=len(CLASSES), default=None, metavar="B",
                    help="added to the class logits' biases after training (with --init and --epochs 0: "
                         "only that)")
    ap.add_argument("--cyclists", type=float, default=CYCLISTS_PER_SCENE, metavar="MEAN",
                    help="mean cyclists tried per scene (the pool holds 6)")
    ap.add_argument("--cluster-scenes", type=int, default=0, metavar="N",
                    help="fit the class reader on each detection's cluster of returns on N scans (0: none; "
                         "the class is the CNN's at the heatmap peak)")
    ap.add_argument("--cluster-seed", type=int, default=None, help="seed of those scans (default: --seed)")
    ap.add_argument("--cluster-cyclists", type=float, default=CYCLISTS_PER_SCENE, metavar="MEAN",
                    help="mean cyclists tried per scene of those scans (as --cyclists)")
    ap.add_argument("--cluster-logit-offsets", type=float, nargs=len(CLASSES), default=None, metavar="B",
                    help="added to the cluster class reader's logits at run time")
    args = ap.parse_args(argv)
    if (message := extras.missing_message("torch", "training the learned detector")) is not None:
        print(message, file=sys.stderr)
        return 2
    lidar_settings = {"vfov": math.radians(args.lidar_vfov)}

    import torch

    widths = list(args.widths)
    init_meta = None
    if args.init is not None:
        from addt_dsl.stack.learned import load_weights

        init_meta = load_weights(args.init)[1]
        widths = list(init_meta["widths"])
    model, timing = train(args.seed, args.scenes, args.epochs, args.batch, args.threads, args.lr,
                          cache=args.cache, device=args.device, widths=tuple(widths),
                          lidars=tuple(args.lidars), lidar_p=None if args.lidar_p is None else tuple(args.lidar_p),
                          lidar_settings=lidar_settings, init=args.init, class_weights=args.class_weights,
                          cyclists=args.cyclists, logit_offsets=args.class_logit_offsets)
    meta = {
        "seed": args.seed, "scenes": args.scenes if args.epochs or args.init is None else 0,
        "epochs": args.epochs, "batch": args.batch, "lr": args.lr,
        "threads": args.threads, "lidars": args.lidars, "lidar_p": args.lidar_p, "threshold": args.threshold,
        "widths": widths, "in_channels": model.in_channels, "cyclists": args.cyclists,
        "class_weights": args.class_weights,
        "class_logit_offsets": args.class_logit_offsets,
        "command": "python -m addt_dsl.stack.train " + " ".join(sys.argv[1:] if argv is None else argv),
        "classes": list(CLASSES),
        "grid": {"x_min": GRID.x_min, "y_min": GRID.y_min, "cell_m": GRID.cell_m, "nx": GRID.nx, "ny": GRID.ny},
        "torch": str(torch.__version__), **timing,
    }
    meta["lidar_vfov_deg"] = args.lidar_vfov
    if args.cluster_scenes:
        seed = args.seed if args.cluster_seed is None else args.cluster_seed
        model.cluster_classes, meta["cluster"] = fit_cluster_classes(
            model, seed, args.cluster_scenes, tuple(args.lidars), lidar_settings, cyclists=args.cluster_cyclists)
        meta["cluster"]["logit_offsets"] = args.cluster_logit_offsets
    if init_meta is not None:  # the run this one started from, and what it cost
        meta["init"] = {"path": str(args.init), "meta": init_meta}
        meta["train_s_total"] = round(timing["train_s"] + init_meta.get("train_s_total", init_meta["train_s"]), 1)
    save_weights(model, meta, args.out, "generation")
    return 0


def fit_cluster_classes(model, seed: int, scenes: int, lidars: tuple[str, ...], lidar_settings: dict | None,
                        iterations: int = 200, log=print, cyclists: float = CYCLISTS_PER_SCENE):
    """The cluster class reader (`cluster_class.TreeEnsemble`) for `model`'s detections on
    `scenes` scans of the default scenes (seed `seed`; `cyclists`: see `synth.sample_scene`),
    and its timing and sample counts."""
    import tempfile

    import torch

    from addt_dsl.stack import cluster_class
    from addt_dsl.stack.learned import LearnedPerception

    t0 = time.perf_counter()
    samples = generate(scenes, seed, lidars=lidars, lidar_settings=lidar_settings, cyclists=cyclists)
    t_gen = time.perf_counter() - t0
    with tempfile.TemporaryDirectory() as tmp:  # the runtime node, so the features are the loop's
        path = Path(tmp) / "cnn.pt"
        torch.save({"state_dict": model.cpu().state_dict(), "meta": {"widths": [
            model.backbone[f"conv{k}"].out_channels for k in range(3)], "classes": list(CLASSES)}}, path)
        node = LearnedPerception({}, weights=path)
    feats, labels, _ = cluster_class.labelled_clusters(samples, node.detect_raw)
    clf = cluster_class.fit(feats, labels, seed, iterations)
    t_fit = time.perf_counter() - t0 - t_gen
    counts = np.bincount(labels, minlength=len(CLASSES)).tolist()
    log(f"cluster classes: {len(labels)} matched detections on {scenes} scans ("
        + ", ".join(f"{n} {c}" for c, n in zip(CLASSES, counts)) + f"); scans {t_gen:.0f} s, fit {t_fit:.0f} s")
    info = {"scenes": scenes, "seed": seed, "cyclists": cyclists, "iterations": iterations,
            "features": list(cluster_class.FEATURES), "detections": counts, "generate_s": round(t_gen, 1),
            "fit_s": round(t_fit, 1)}
    return cluster_class.TreeEnsemble.from_sklearn(clf), info


def save_weights(model, meta: dict, path: Path, data_step: str) -> None:
    """Write a trained model's weights with the metadata that says how they were made (a
    store ties results to them), and say so; `data_step` names how the training data came
    (its time is `meta["generate_s"]`)."""
    import torch

    state = {k: v.detach().clone() for k, v in model.state_dict().items()}
    ensemble = getattr(model, "cluster_classes", None)
    if ensemble is not None:  # the cluster class reader: flat arrays beside the layers (`cluster_class`)
        from addt_dsl.stack.cluster_class import PREFIX

        state.update({PREFIX + k: torch.from_numpy(np.ascontiguousarray(v)) for k, v in ensemble.state().items()})
    path.parent.mkdir(parents=True, exist_ok=True)
    torch.save({"state_dict": state, "meta": meta}, path)
    print(f"wrote {path} ({path.stat().st_size / 1024:.0f} KiB; "
          f"{data_step} {meta['generate_s']} s, training {meta['train_s']} s)")


if __name__ == "__main__":
    raise SystemExit(main())
