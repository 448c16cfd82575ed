"""Train and evaluate the camera BEV network on twin renders: `python -m addt_dsl.stack.camera_train`.

    nice -n 10 python -m addt_dsl.stack.camera_train --seed 0 --out addt_dsl/stack/camera_bev_weights.pt
    python -m addt_dsl.stack.camera_train --evaluate [--weights W] [--scenes 400] [--seed 1000003]

Scenes are the lidar detector's (`synth.sample_scene`: lanes of cars and trucks, parked
vehicles, pedestrians and cyclists), on a road mesh the runtime builds (`roadmesh`:
surface, markings, verges; straight or curved, 1-3 lanes each way), rendered by the
runtime's own `Camera` class at the rig of `bev_grid.DETECTOR_RIG`. An object's "hits"
are its visible pixels in all cameras (from the renderer's body-id image): objects with
at least `MIN_PIXELS_TARGET` are positives, and evaluation counts those with
`--min-pixels` (default 6, the colour detector's blob minimum). The loss is the lidar
detector's (`train.centernet_loss`). Reproducible from the seed on the same thread count.

`--evaluate` prints the lidar detector's tables (`evaluate.format_table`, per distance
band and per class) for held-out scenes, and the inference cost per frame.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from addt_dsl import extras
from addt_dsl.stack.bev_grid import BOX_CHANNELS, CLASSES, DETECTOR_RIG, GRID, encode_targets
from addt_dsl.stack.synth import PARK_X0, POOL, in_grid, road_point, sample_scene, wrap_angle
from addt_dsl.stack.train import save_weights

MIN_PIXELS_TARGET = 3
ROAD_KAPPAS = (0.0, 0.0, 0.002, -0.002, 0.004, -0.004)


@dataclass
class CameraSample:
    images: np.ndarray  # (cameras, H, W, 3) uint8
    boxes: np.ndarray  # (M, 5) x, y, heading, length, width (vehicle frame)
    hits: np.ndarray  # (M,) visible pixels over all cameras
    classes: np.ndarray  # (M,) index into CLASSES

    # What `evaluate.evaluate` hands its detector.
    @property
    def points(self) -> np.ndarray:
        return self.images

    sensor_xy = (0.0, 0.0)


class _RenderWorld:
    """A visual pybullet world (the runtime's) with one road and a pool of coloured bodies."""

    def __init__(self, kappa: float, n_right: int, n_left: int):
        from addt_dsl import road as R
        from addt_dsl.runtime.roadmesh import build_scene
        from addt_dsl.runtime.world import PhysicsWorld
        from addt_dsl.vehicles import CAR, VEHICLES

        self.physics = PhysicsWorld(visual=True)
        # The road's station 250 m is the origin of `sample_scene`'s arc.
        x0, y0, h0 = road_point(kappa, -250.0, 0.0)
        geometry = R.arc(500.0, kappa) if kappa else R.line(500.0)
        build_scene(self.physics, [R.build_road("r", [geometry], n_left, n_right, 3.5, start=(x0, y0, h0))])
        self.physics.add_box("ego", CAR.length_m, CAR.width_m, CAR.height_m)  # no colour: cameras see through it
        self.pool = []
        for kind, length, width, height, count in POOL:
            for k in range(count):
                name = f"{kind}_{k}"
                self.physics.add_box(name, length, width, height, VEHICLES[kind].rgba)
                self.pool.append((name, kind, length, width, height))
        self.body_index = {self.physics.bodies[p[0]]: i for i, p in enumerate(self.pool)}
        self.pose = (0.0, 0.0, 0.0, 0.0)

    def ego_pose(self):
        return self.pose

    def render(self, *args, **kwargs):
        return self.physics.render(*args, **kwargs)


class CameraSceneGenerator:
    """Labelled rig renders of random scenes (one world per road layout, built on demand)."""

    def __init__(self, seed: int, rig_settings: dict | None = None):
        from addt_dsl.runtime.sensors import Camera, CameraRig

        self.rng = np.random.default_rng(seed)
        self.rig = CameraRig("rig", {**DETECTOR_RIG.settings(), **(rig_settings or {})})
        self.cameras = []
        for k, ext in enumerate(self.rig.camera_extrinsics(self.rig.nominal)):
            cam = Camera(f"rig.{k}", {**self.rig.settings, "segmentation": "on"})
            cam.actual = ext
            self.cameras.append(cam)
        self.worlds: dict[tuple, _RenderWorld] = {}

    def close(self):
        for w in self.worlds.values():
            w.physics.close()

    def sample(self) -> CameraSample:
        rng = self.rng
        layout = (float(rng.choice(ROAD_KAPPAS)), int(rng.integers(1, 4)), int(rng.integers(0, 3)))
        if layout not in self.worlds:
            self.worlds[layout] = _RenderWorld(*layout)
        world = self.worlds[layout]
        ego: list = []
        poses = sample_scene(rng, world.pool, road=layout, ego=ego)
        return self._render(world, poses, tuple(ego))

    def render(self, objects: list[tuple[str, float, float, float]],
               layout: tuple[float, int, int] = (0.0, 2, 1)) -> CameraSample:
        """Render a given scene: `objects` are (kind, x, y, heading) in the ego's vehicle
        frame; the ego in the middle of the rightmost lane of a road `layout` (curvature,
        lanes right, lanes left)."""
        if layout not in self.worlds:
            self.worlds[layout] = _RenderWorld(*layout)
        world = self.worlds[layout]
        free = {kind: [i for i, p in enumerate(world.pool) if p[1] == kind] for kind in CLASSES}
        poses = [(free[kind].pop(0), x, y, h) for kind, x, y, h in objects]
        t = -(layout[1] - 0.5) * 3.5
        return self._render(world, poses, road_point(layout[0], 0.0, t))

    def _render(self, world: _RenderWorld, poses, ego) -> CameraSample:
        ex, ey, eh = ego
        world.pose = (ex, ey, eh, 0.0)
        phys = world.physics
        phys.set_pose("ego", ex, ey, 0.75, eh)
        c, s = math.cos(eh), math.sin(eh)
        used, boxes, classes = set(), [], []
        for idx, x, y, h in poses:
            name, kind, length, width, height = world.pool[idx]
            phys.set_pose(name, ex + c * x - s * y, ey + s * x + c * y, height / 2, eh + h)
            used.add(idx)
            boxes.append((x, y, wrap_angle(h), length, width))
            classes.append(CLASSES.index(kind))
        for idx, (name, _, _, _, height) in enumerate(world.pool):
            if idx not in used:
                phys.set_pose(name, PARK_X0 + 30.0 * idx, 0.0, height / 2, 0.0)
        images = np.empty((len(self.cameras), self.rig.height, self.rig.width, 3), dtype=np.uint8)
        pixels = np.zeros(len(world.pool), dtype=np.int64)
        for k, cam in enumerate(self.cameras):
            frame = cam.capture(world, 0.0)
            images[k] = frame.data["image"]
            ids = frame.data["segmentation"]
            for body, n in zip(*np.unique(ids[ids >= 0], return_counts=True)):
                slot = world.body_index.get(int(body))
                if slot is not None:
                    pixels[slot] += int(n)
        hits = np.array([pixels[idx] for idx, *_ in poses], dtype=np.int64)
        return CameraSample(images, np.array(boxes, dtype=np.float64).reshape(-1, 5), hits,
                            np.array(classes, dtype=np.int64))


def generate(n: int, seed: int) -> list[CameraSample]:
    gen = CameraSceneGenerator(seed)
    try:
        return [gen.sample() for _ in range(n)]
    finally:
        gen.close()


def make_targets(samples: list[CameraSample]):
    hx, hy = GRID.head_shape
    heat = np.zeros((len(samples), hx, hy), dtype=np.float32)
    reg = np.zeros((len(samples), BOX_CHANNELS + 1, hx, hy), dtype=np.float32)
    mask = np.zeros((len(samples), hx, hy), dtype=np.float32)
    for k, s in enumerate(samples):
        keep = in_grid(s.boxes) & (s.hits >= MIN_PIXELS_TARGET)
        heat[k], reg[k], mask[k] = encode_targets(s.boxes[keep], classes=s.classes[keep])
    return heat, reg, mask


def train(seed: int, scenes: int, epochs: int, batch: int, threads: int, lr: float, log=print):
    import torch

    from addt_dsl.stack.camera_bev import CameraBevNet, RigGeometry, images_tensor
    from addt_dsl.stack.train import fit

    torch.set_num_threads(threads)
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    t0 = time.perf_counter()
    gen = CameraSceneGenerator(seed)
    try:
        samples = [gen.sample() for _ in range(scenes)]
        rig = gen.rig
    finally:
        gen.close()
    heat_all, reg_all, mask_all = make_targets(samples)
    t_gen = time.perf_counter() - t0
    seen = np.bincount(np.concatenate([s.classes[s.hits >= MIN_PIXELS_TARGET] for s in samples]),
                       minlength=len(CLASSES))
    log(f"rendered {scenes} scenes in {t_gen:.1f} s ("
        + ", ".join(f"{n} {c}" for c, n in zip(CLASSES, seen.tolist())) + " visible)")
    geometry = RigGeometry(rig.intrinsics, rig.camera_extrinsics(rig.nominal), rig.width, rig.height)
    model = CameraBevNet()
    all_images = np.stack([s.images for s in samples])

    def forward(idx):
        idx = np.sort(idx)
        heat_logits, box = model.forward_images(images_tensor(all_images[idx]), geometry.table, geometry.position)
        return heat_logits, box, (torch.from_numpy(a[idx]) for a in (heat_all, reg_all, mask_all))

    t_train = fit(model, lr, scenes, batch, epochs, rng, forward, log)
    return model.eval(), {"generate_s": round(t_gen, 1), "train_s": round(t_train, 1)}


def evaluate_weights(weights: Path, scenes: int, seed: int, min_pixels: int, threshold: float | None,
                     log=print) -> None:
    from addt_dsl.runtime.sensors import CameraRig
    from addt_dsl.stack.camera_bev import CameraBevPerception
    from addt_dsl.stack.evaluate import evaluate, format_class_table, format_table

    node = CameraBevPerception({} if threshold is None else {"detect_threshold": threshold}, weights=weights)
    rig = CameraRig("rig", DETECTOR_RIG.settings())
    geometry = node.geometry(rig)
    samples = generate(scenes, seed)
    times: list[float] = []

    def detector(images, _sensor_xy):
        t = time.perf_counter()
        out = node.detect(images, geometry)
        times.append(time.perf_counter() - t)
        return out

    kinds: dict = {}
    classes: dict = {}
    stats = evaluate(samples, detector, min_pixels, kinds, classes)
    log(format_table(stats, f"{len(samples)} held-out scenes (seed {seed}), rig {DETECTOR_RIG.clause()}, "
                            f"threshold {node.threshold:g}, ground truth with >= {min_pixels} visible pixels"))
    log("recall within 40 m by kind: " + ", ".join(
        f"{kind} {found / gt:.3f} ({gt})" for kind, (found, gt) in sorted(kinds.items()) if gt))
    log(format_class_table(classes))
    t = np.array(times) * 1e3
    log(f"inference per frame (one thread): median {np.median(t):.1f} ms, p90 {np.percentile(t, 90):.1f} ms "
        f"over {len(t)} frames")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m addt_dsl.stack.camera_train", description=__doc__.split("\n")[0])
    ap.add_argument("--seed", type=int, default=None, help="default 0 (training), 1000003 (--evaluate)")
    ap.add_argument("--out", type=Path, default=Path(__file__).with_name("camera_bev_weights.pt"))
    ap.add_argument("--scenes", type=int, default=None, help="default 4500 (training), 400 (--evaluate)")
    ap.add_argument("--epochs", type=int, default=7)
    ap.add_argument("--batch", type=int, default=16)
    ap.add_argument("--lr", type=float, default=3e-3)
    ap.add_argument("--threads", type=int, default=1, help="CPU threads (reproducible per thread count)")
    ap.add_argument("--threshold", type=float, default=None, help="detection threshold (stored with the weights)")
    ap.add_argument("--evaluate", action="store_true", help="evaluate weights on held-out scenes instead")
    ap.add_argument("--weights", type=Path, default=None, help="weights to evaluate (default: the shipped ones)")
    ap.add_argument("--min-pixels", type=int, default=6, help="evaluation: visible pixels for a box to count")
    args = ap.parse_args(argv)
    if (message := extras.missing_message("torch", "training the camera BEV network")) is not None:
        print(message, file=sys.stderr)
        return 2
    if args.evaluate:
        from addt_dsl.stack.camera_bev import WEIGHTS_PATH

        evaluate_weights(args.weights or WEIGHTS_PATH, args.scenes or 400,
                         1_000_003 if args.seed is None else args.seed, args.min_pixels, args.threshold)
        return 0

    import torch

    from addt_dsl.stack.rig_lift import FEATURE_STRIDE, LIFT_HEIGHTS_M

    seed = 0 if args.seed is None else args.seed
    scenes = args.scenes or 4500
    model, timing = train(seed, scenes, args.epochs, args.batch, args.threads, args.lr)
    meta = {"seed": seed, "scenes": scenes, "epochs": args.epochs, "batch": args.batch, "lr": args.lr,
            "threads": args.threads, "threshold": 0.35 if args.threshold is None else args.threshold,
            "widths": [16, 24, 32], "features": model.features, "heights": list(LIFT_HEIGHTS_M),
            "feature_stride": FEATURE_STRIDE,
            "classes": list(CLASSES), "rig": DETECTOR_RIG.settings(), "torch": str(torch.__version__), **timing}
    save_weights(model, meta, args.out, "rendering")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
