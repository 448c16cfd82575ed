"""Learned perception: a small CenterNet-style CNN over a lidar BEV grid (torch).

Points (sensor frame) are mapped to the vehicle frame with the *nominal* extrinsics and
scattered into the 6×152×64 grid of `bev_grid` (0.8 m cells, ±60.8 m × ±25.6 m). The
network is strided from the first layer (PERFORMANCE.md: a stride-1 first layer costs
~10×), goes down to 1/8 resolution for context (a truck's centre is 6 m from the rear
face the lidar sees) and back up to a 76×32 head grid of 1.6 m cells (fine enough that
cars in adjacent lanes are separate peaks). Per head cell it predicts an object-centre
heatmap, a sub-cell offset, log length, log width and heading as (sin, cos):

    backbone.conv0     conv 3×3 s2   6→16   76×32  ─────────────────────┐
    backbone.conv1     conv 3×3 s2  16→24   38×16  ──────────┐          │
    backbone.conv2     conv 3×3 s2  24→32   19×8             │          │
    backbone.conv3     conv 3×3     32→32   19×8             │          │
    neck.lateral       conv 1×1     32→24   → ×2 nearest, + ─┘          │
    neck.fuse          conv 3×3     24→24   38×16                       │
    neck.lateral_fine  conv 1×1     24→16   → ×2 nearest, + ────────────┘
    neck.fine          conv 3×3     16→16   76×32
    head.center        conv 1×1     16→1    heatmap logits
    head.box           conv 1×1     16→6    offset x/y, log l/w, sin/cos heading

One frame per inference: velocity is not estimated here but by the tracker from
successive detections (objects carry `vx = vy = nan`, "not measured").

Tensor fault sites are the named layers (`perception.backbone.conv0`, ...): a site's
*weights* are its kernel followed by its bias in one flat index space, its
*activations* are the layer's output (before the ReLU), batch size 1. See
`flip_weight_bits` and `flip_activation_bits`, built on `tensorfaults`.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from addt_dsl.stack.bev_grid import GRID, LAYER_SITES, build_grid, decode, sensor_points_to_vehicle
from addt_dsl.stack.nodes import Obj
from addt_dsl.stack.tensorfaults import ActivationFlip, flip_bits

WEIGHTS_PATH = Path(__file__).with_name("perception_weights.pt")
DEFAULT_THRESHOLD = 0.35


class BevDetector(nn.Module):
    """The detector network; layer names are the tensor fault sites (`bev_grid.LAYER_SITES`)."""

    def __init__(self, widths: tuple[int, int, int] = (16, 24, 32), in_channels: int = 6):
        super().__init__()
        c1, c2, c3 = widths
        # Named convN, not 0..3: fault targets are dotted names in the DSL (`perception.backbone.conv0`).
        self.backbone = nn.ModuleDict({
            "conv0": nn.Conv2d(in_channels, c1, 3, 2, 1),
            "conv1": nn.Conv2d(c1, c2, 3, 2, 1),
            "conv2": nn.Conv2d(c2, c3, 3, 2, 1),
            "conv3": nn.Conv2d(c3, c3, 3, 1, 1),
        })
        self.neck = nn.ModuleDict({
            "lateral": nn.Conv2d(c3, c2, 1), "fuse": nn.Conv2d(c2, c2, 3, 1, 1),
            "lateral_fine": nn.Conv2d(c2, c1, 1), "fine": nn.Conv2d(c1, c1, 3, 1, 1),
        })
        self.head = nn.ModuleDict({"center": nn.Conv2d(c1, 1, 1), "box": nn.Conv2d(c1, 6, 1)})
        nn.init.constant_(self.head["center"].bias, -math.log((1 - 0.02) / 0.02))  # prior p = 0.02

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        b, neck = self.backbone, self.neck
        x0 = F.relu(b["conv0"](x), inplace=True)
        x1 = F.relu(b["conv1"](x0), inplace=True)
        x = F.relu(b["conv2"](x1), inplace=True)
        x = F.relu(b["conv3"](x), inplace=True)
        x = F.interpolate(neck["lateral"](x), scale_factor=2.0, mode="nearest") + x1
        x = F.relu(neck["fuse"](x), inplace=True)
        x = F.interpolate(neck["lateral_fine"](x), scale_factor=2.0, mode="nearest") + x0
        x = F.relu(neck["fine"](x), inplace=True)
        return self.head["center"](x), self.head["box"](x)

    def layers(self) -> dict[str, nn.Conv2d]:
        named = dict(self.named_modules())
        return {name: named[name] for name in LAYER_SITES}


_CACHE: dict[Path, tuple[dict, dict]] = {}


def load_weights(path: Path = WEIGHTS_PATH) -> tuple[dict, dict]:
    """(state dict, metadata) from a weights file, cached per process (read-only: copy it)."""
    path = Path(path)
    if path not in _CACHE:
        blob = torch.load(path, map_location="cpu", weights_only=True)
        _CACHE[path] = (blob["state_dict"], blob.get("meta", {}))
    return _CACHE[path]


def load_model(path: Path = WEIGHTS_PATH, device: str = "cpu") -> tuple[BevDetector, dict]:
    """A fresh detector with the shipped weights: weight faults in one run touch only its copy."""
    state, meta = load_weights(path)
    model = BevDetector(tuple(meta.get("widths", (16, 24, 32))))
    model.load_state_dict(state)
    return model.to(device).eval(), meta


class LearnedPerception:
    """The `perception learned` node: lidar frame → grid → CNN → objects in world coordinates."""

    name = "perception"
    sites = ("perception.x", "perception.y")
    tensor_sites = tuple(f"perception.{n}" for n in LAYER_SITES)

    def __init__(self, settings: dict, ctx=None, weights: Path = WEIGHTS_PATH, device: str = "cpu"):
        # One intra-op thread: inference is tiny, threads only add jitter and contention
        # with parallel runs (and keep results independent of the machine's core count).
        torch.set_num_threads(1)
        self.model, self.meta = load_model(weights, device)
        self.device = device
        self.threshold = float(settings.get("detect_threshold", self.meta.get("threshold", DEFAULT_THRESHOLD)))
        self._logit_threshold = math.log(self.threshold / (1.0 - self.threshold))
        self._grid = np.zeros(GRID.shape, dtype=np.float32)
        self._input = torch.from_numpy(self._grid)[None]  # shares memory with the grid buffer
        self._layers = self.model.layers()
        self._armed: list[ActivationFlip] = []
        self.last_activation_flips: list[tuple[str, tuple]] = []
        # Warm-up: the first inference pays one-off kernel set-up, which would otherwise
        # show as a latency spike in the first frame of `latency measured` runs.
        self.detect(np.zeros((0, 3)), (0.0, 0.0))

    # ---- the node
    def run(self, frame, world, sensor, ego_pose, corrupt) -> list[Obj]:
        points = frame.data["points"]
        nominal = sensor.nominal
        pts = sensor_points_to_vehicle(points, nominal) if len(points) else np.zeros((0, 3))
        boxes = self.detect(pts, (nominal.x, nominal.y))
        x, y, heading, _ = ego_pose
        cos_h, sin_h = math.cos(heading), math.sin(heading)
        objs = []
        for bx, by, bh, length, width, conf in boxes.tolist():
            px = corrupt("perception.x", bx)
            py = corrupt("perception.y", by)
            objs.append(Obj(x + cos_h * px - sin_h * py, y + sin_h * px + cos_h * py, heading + bh,
                            math.nan, math.nan, length, width, conf))
        return objs

    def detect(self, points_vehicle: np.ndarray, sensor_xy: tuple[float, float]) -> np.ndarray:
        """Vehicle-frame points → (N, 6) boxes: x, y, heading, length, width, confidence."""
        build_grid(points_vehicle, sensor_xy, out=self._grid)
        with torch.inference_mode():
            x = self._input if self.device == "cpu" else self._input.to(self.device)
            heat, box = self.model(x)
            heat, box = heat[0, 0].cpu().numpy(), box[0].cpu().numpy()
        self._collect_fired()
        # Threshold on logits (monotone): the sigmoid is only needed at the peaks.
        found = decode(heat, box, self._logit_threshold)
        if len(found):
            with np.errstate(over="ignore"):
                found[:, 5] = 1.0 / (1.0 + np.exp(-found[:, 5]))
        return found

    # ---- tensor fault sites
    def fault_sites(self) -> tuple[str, ...]:
        return self.tensor_sites

    def tensor_modules(self) -> dict[str, nn.Module]:
        """Site name → torch module, for the fault engine's `bitflip ... tensor` hooks."""
        return {f"perception.{name}": layer for name, layer in self._layers.items()}

    def _layer(self, site: str) -> nn.Conv2d:
        name = site.removeprefix("perception.")
        if name not in self._layers:
            raise KeyError(f"unknown tensor site {site!r}; sites: {', '.join(self.tensor_sites)}")
        return self._layers[name]

    def site_numel(self, site: str, tensor: str = "weights") -> int:
        """Elements addressable at a site: kernel + bias (weights) or the output at batch 1."""
        layer = self._layer(site)
        if tensor == "weights":
            return layer.weight.numel() + (layer.bias.numel() if layer.bias is not None else 0)
        if tensor == "activations":
            return int(np.prod(self.activation_shape(site)))
        raise ValueError(f"tensor must be 'weights' or 'activations', not {tensor!r}")

    def activation_shape(self, site: str) -> tuple[int, ...]:
        self._layer(site)
        shapes = _activation_shapes(self.model, self.device)
        return shapes[site.removeprefix("perception.")]

    def flip_weight_bits(self, site: str, flat_indices, bits) -> tuple[list[float], list[float]]:
        """Flip bits in a layer's parameters (persistent for this node's lifetime)."""
        layer = self._layer(site)
        n_w = layer.weight.numel()
        before, after = [], []
        # One at a time, in the caller's order (a repeated index composes).
        for i, b in zip(flat_indices, bits, strict=True):
            i, b = int(i), int(b)
            tensor, k = (layer.weight, i) if i < n_w else (layer.bias, i - n_w)
            if tensor is None:
                raise IndexError(f"{site} has no bias; index {i} is out of range")
            bf, af = flip_bits(tensor.data, [k], [b])
            before += bf
            after += af
        return before, after

    def flip_activation_bits(self, site: str, flat_indices, bits) -> ActivationFlip:
        """Arm a transient flip in a layer's output for the next inference only.

        Returns the armed `ActivationFlip`; after the inference its `fired` holds the
        values before and after (also appended to `last_activation_flips`).
        """
        numel = self.site_numel(site, "activations")
        for i in flat_indices:
            if not 0 <= int(i) < numel:
                raise IndexError(f"activation index {i} out of range for {site} ({numel} elements)")
        flip = ActivationFlip(self._layer(site), flat_indices, bits).arm()
        flip.site = site  # type: ignore[attr-defined]
        self._armed.append(flip)
        return flip

    def _collect_fired(self) -> None:
        self.last_activation_flips = [(f.site, f.fired) for f in self._armed if f.fired is not None]
        self._armed = [f for f in self._armed if f.fired is None]


_SHAPES: dict[str, dict[str, tuple[int, ...]]] = {}


def _activation_shapes(model: BevDetector, device: str) -> dict[str, tuple[int, ...]]:
    """Output shape of every named layer at batch 1 (one dry run, cached)."""
    if device not in _SHAPES:
        shapes = {}
        hooks = [layer.register_forward_hook(
            lambda m, i, o, name=name: shapes.__setitem__(name, tuple(o.shape)))
            for name, layer in model.layers().items()]
        with torch.inference_mode():
            model(torch.zeros((1, *GRID.shape), device=device))
        for h in hooks:
            h.remove()
        _SHAPES[device] = shapes
    return _SHAPES[device]
