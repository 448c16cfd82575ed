"""Camera BEV perception (`stack bev perception camera_bev`): surround cameras → BEV grid → objects.

The paper's system under test sees through six cameras and a learned network that
lifts them to a bird's-eye-view grid (Fast-BEV). This is that pipeline, small enough to
train on a CPU in minutes (`python -m addt_dsl.stack.camera_train`):

    encoder.conv0   conv 3×3      3→12    per camera, on its 40×128 image
    encoder.conv1   conv 3×3     12→16
    encoder.conv2   conv 1×1     16→8     the per-pixel features that are lifted
    lift            `rig_lift.lift_table`: each BEV cell at 5 heights takes the feature of
                    the pixel it projects to (nominal intrinsics and extrinsics), no depth
                    estimate; + 3 position channels → 43 × 152 × 64
    backbone/neck/head   the lidar detector's BEV network (`learned.BevDetector`, widths 16/24/32)

and the lidar detector's CenterNet heads and decoding (`bev_grid.decode`): boxes with a
class, no velocity (the tracker estimates it). RGB only (no depth image), as the paper's
cameras. Tensor fault sites are the named layers (`bev_grid.CAMERA_BEV_TENSOR_SITES`),
with the lidar detector's flip utilities (`tensorfaults`); the network runs dense (every
pixel of every camera changes every frame), so fault hooks are ordinary forward hooks.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from addt_dsl.kernel import exp
from addt_dsl.lru import LruCache
from addt_dsl.stack.bev_grid import CAMERA_BEV_SITES, CLASSES, GRID, decode
from addt_dsl.stack.learned import SHAPES_CACHE_SIZE, BevDetector, boxes_to_world, load_weights, one_intra_op_thread
from addt_dsl.stack.nodes import Obj
from addt_dsl.stack.rig_lift import FEATURE_STRIDE, LIFT_HEIGHTS_M, lift_table, position_channels
from addt_dsl.stack.tensorfaults import ActivationFlip, ConvTensorSites

WEIGHTS_PATH = Path(__file__).with_name("camera_bev_weights.pt")
DEFAULT_THRESHOLD = 0.35
FEATURES = 8


class CameraBevNet(BevDetector):
    """Per-camera encoder + fixed lift + the BEV detector; layer names are the fault sites."""

    sites = CAMERA_BEV_SITES

    def __init__(self, widths: tuple[int, int, int] = (16, 24, 32), features: int = FEATURES,
                 heights: int = len(LIFT_HEIGHTS_M), classes: int = len(CLASSES)):
        super().__init__(widths, in_channels=features * heights + 3, classes=classes)
        self.features = features
        self.encoder = nn.ModuleDict({
            "conv0": nn.Conv2d(3, 12, 3, FEATURE_STRIDE, 1),
            "conv1": nn.Conv2d(12, 16, 3, 1, 1),
            "conv2": nn.Conv2d(16, features, 1),
        })

    def lift(self, images: torch.Tensor, table: torch.Tensor, position: torch.Tensor) -> torch.Tensor:
        """(B, cameras, 3, H, W) images in [0, 1] → (B, C·heights + 3, nx, ny) BEV features.

        `table`: (heights, nx, ny) long indices (`rig_lift.lift_table`); `position`:
        (3, nx, ny) (`rig_lift.position_channels`)."""
        b, n = images.shape[:2]
        e = self.encoder
        x = F.relu(e["conv0"](images.flatten(0, 1)))
        x = F.relu(e["conv1"](x))
        x = F.relu(e["conv2"](x))  # (B·n, C, hf, wf)
        c = x.shape[1]
        flat = x.view(b, n, c, -1).permute(0, 2, 1, 3).reshape(b, c, -1)
        flat = torch.cat([flat, flat.new_zeros(b, c, 1)], dim=2)  # the slot of unseen cells
        # index_select: its backward is an index_add (advanced indexing's is a slow sort on CPU).
        bev = torch.index_select(flat, 2, table.flatten()).view(b, c * table.shape[0], *table.shape[1:])
        return torch.cat([bev, position.expand(b, -1, -1, -1)], dim=1)

    def forward_images(self, images, table, position):
        return self.forward(self.lift(images, table, position))




def load_model(path: Path = WEIGHTS_PATH) -> tuple[CameraBevNet, dict]:
    """A fresh network with the shipped weights: weight faults in one run touch only its copy."""
    state, meta = load_weights(path)
    model = CameraBevNet(tuple(meta["widths"]), meta["features"], len(meta["heights"]), len(meta["classes"]))
    model.load_state_dict(state)
    return model.eval(), meta


class RigGeometry:
    """The lift table and position channels of a rig (nominal calibration), as tensors."""

    def __init__(self, intrinsics: np.ndarray, extrinsics, width: int, height: int):
        self.table = torch.from_numpy(lift_table(intrinsics, extrinsics, width, height))
        ex = extrinsics[0]
        self.position = torch.from_numpy(position_channels(origin_xy=(ex.x, ex.y)))


def images_tensor(images: np.ndarray) -> torch.Tensor:
    """(cameras, H, W, 3) uint8 (or a batch of them) → float (…, cameras, 3, H, W) in [0, 1]."""
    t = torch.from_numpy(np.ascontiguousarray(images))
    if t.dtype != torch.uint8:  # float images in [0, 1]
        return t.float().movedim(-1, -3)
    return t.movedim(-1, -3).float().div_(255.0)


class CameraBevPerception(ConvTensorSites):
    """The `perception camera_bev` node: a `camera_rig` frame → network → objects in world coordinates."""

    name = "perception"
    sites = ("perception.x", "perception.y")
    tensor_sites = tuple(f"perception.{n}" for n in CAMERA_BEV_SITES)

    def __init__(self, settings: dict, ctx=None, weights: Path = WEIGHTS_PATH):
        self.model, self.meta = load_model(weights)
        self.threshold = float(settings.get("detect_threshold", self.meta.get("threshold", DEFAULT_THRESHOLD)))
        self._logit_threshold = math.log(self.threshold / (1.0 - self.threshold))
        self._layers = self.model.layers()
        self._geometry: dict[tuple, RigGeometry] = {}
        self._armed: list[ActivationFlip] = []
        self.last_activation_flips: list[tuple[str, tuple]] = []

    def geometry(self, sensor) -> RigGeometry:
        """The lift for a rig sensor's nominal calibration (cached: it changes only with the sensor)."""
        exts = sensor.camera_extrinsics(sensor.nominal)
        key = (sensor.width, sensor.height, tuple(sensor.intrinsics.ravel()),
               tuple((e.x, e.y, e.z, e.roll, e.pitch, e.yaw) for e in exts))
        if key not in self._geometry:
            self._geometry[key] = RigGeometry(sensor.intrinsics, exts, sensor.width, sensor.height)
        return self._geometry[key]

    # ---- the node
    def run(self, frame, sensor, ego_pose, corrupt) -> list[Obj]:
        boxes = self.detect(frame.data["images"], self.geometry(sensor))
        return boxes_to_world(boxes, ego_pose, corrupt)

    def detect(self, images: np.ndarray, geometry: RigGeometry) -> np.ndarray:
        """(cameras, H, W, 3) images → (N, 7) boxes in the vehicle frame: x, y, heading,
        length, width, confidence, class (index into `bev_grid.CLASSES`)."""
        with torch.inference_mode(), one_intra_op_thread():
            heat, box = self.model.forward_images(images_tensor(images)[None], geometry.table, geometry.position)
            heat, box = heat[0, 0].numpy(), box[0].numpy()
        self._collect_fired()
        found = decode(heat, box, self._logit_threshold)
        if len(found):
            with np.errstate(over="ignore"):
                found[:, 5] = 1.0 / (1.0 + exp.over(-found[:, 5]))
        return found

    # ---- tensor fault sites (ConvTensorSites): the shape of a site's output
    def activation_shape(self, site: str) -> tuple[int, ...]:
        """A site's output shape for one frame of the trained rig (batch 1; the encoder's
        batch is the cameras)."""
        self._layer(site)
        return _activation_shapes(self.model, self.meta)[site.removeprefix("perception.")]


_SHAPES: LruCache[tuple, dict[str, tuple[int, ...]]] = LruCache(SHAPES_CACHE_SIZE)  # (widths, rig) -> shapes


def _activation_shapes(model: CameraBevNet, meta: dict) -> dict[str, tuple[int, ...]]:
    rig = meta["rig"]
    key = (tuple(layer.out_channels for layer in model.layers().values()), rig["cameras"], rig["height"],
           rig["width"])
    shapes = _SHAPES.get(key)
    if shapes is None:
        shapes = {}
        hooks = [layer.register_forward_hook(lambda m, i, o, name=name: shapes.__setitem__(name, tuple(o.shape)))
                 for name, layer in model.layers().items()]
        hf, wf = -(-rig["height"] // FEATURE_STRIDE), -(-rig["width"] // FEATURE_STRIDE)
        table = torch.full((len(meta["heights"]), GRID.nx, GRID.ny), rig["cameras"] * hf * wf, dtype=torch.long)
        with torch.inference_mode():
            model.forward_images(torch.zeros((1, rig["cameras"], 3, rig["height"], rig["width"])), table,
                                 torch.zeros((3, GRID.nx, GRID.ny)))
        for h in hooks:
            h.remove()
        _SHAPES.put(key, shapes)
    return shapes
