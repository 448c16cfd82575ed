"""Learned perception: a small CenterNet-style CNN over a lidar BEV grid (torch).

Points (sensor frame) are mapped to the vehicle frame with the *nominal* extrinsics and
scattered into the 8×152×64 grid of `bev_grid` (0.8 m cells, ±60.8 m × ±25.6 m). The
network is strided from the first layer (PERFORMANCE.md: a stride-1 first layer costs
~10×), goes down to 1/8 resolution for context (a truck's centre is 6 m from the rear
face the lidar sees) and back up to a 76×32 head grid of 1.6 m cells (fine enough that
cars in adjacent lanes are separate peaks). Per head cell it predicts an object-centre
heatmap, a sub-cell offset, log length, log width and the box axis as (sin 2θ, cos 2θ):

    backbone.conv0     conv 3×3 s2   8→32   76×32  ─────────────────────┐
    backbone.conv1     conv 3×3 s2  32→48   38×16  ──────────┐          │
    backbone.conv2     conv 3×3 s2  48→64   19×8             │          │
    backbone.conv3     conv 3×3     64→64   19×8             │          │
    neck.lateral       conv 1×1     64→48   → ×2 nearest, + ─┘          │
    neck.fuse          conv 3×3     48→48   38×16                       │
    neck.lateral_fine  conv 1×1     48→32   → ×2 nearest, + ────────────┘
    neck.fine          conv 3×3     32→32   76×32
    head.center        conv 1×1     32→1    heatmap logits
    head.box           conv 1×1     32→10   offset x/y, log l/w, box axis (sin 2θ, cos 2θ),
                                            class logits (car, truck, pedestrian, cyclist)

The class of each detection is then read from its own cluster of returns (how many, how
far, how high, how wide and deep, and the class logits at the peak) by the tree ensemble
shipped in the same weights file (`cluster_class`); weights without one keep the class
at the heatmap peak.

One frame per inference: velocity is not estimated here but by the tracker from
successive detections (objects carry `vx = vy = nan`, "not measured").

Tensor fault sites are the named layers (`perception.backbone.conv0`, ...): a site's
*weights* are its kernel followed by its bias in one flat index space, its
*activations* are the layer's output (before the ReLU), batch size 1. See
`flip_weight_bits` and `flip_activation_bits`, built on `tensorfaults`.
"""

from __future__ import annotations

import math
import os
from contextlib import contextmanager
from pathlib import Path

import numpy as np

# oneDNN (torch's convolutions on the CPU) picks its kernels by the CPU's instruction set, and
# its AVX-512 kernels sum in another order than its AVX2 ones: a learned run's trace would
# depend on the machine. Capped at AVX2 (any x86-64 CPU since 2013 has it) unless the
# environment says otherwise (`ONEDNN_MAX_CPU_ISA=ALL`: the machine's own, ~20-30 % faster
# forwards measured here). Read by oneDNN at its first convolution: set before torch runs one.
os.environ.setdefault("ONEDNN_MAX_CPU_ISA", "AVX2")

import torch  # noqa: E402
import torch.nn.functional as F  # noqa: E402
from torch import nn  # noqa: E402

from addt_dsl.kernel import exp
from addt_dsl.lru import LruCache
from addt_dsl.stack import cluster_class
from addt_dsl.stack.bev_grid import (BOX_CHANNELS, CHANNELS, CLASSES, GRID, LAYER_SITES, build_grid_region,
                                     decode, sensor_points_to_vehicle)
from addt_dsl.stack.cluster_class import TreeEnsemble
from addt_dsl.stack.nodes import Obj, vehicle_to_world
from addt_dsl.stack.tensorfaults import ActivationFlip, ConvTensorSites

WEIGHTS_PATH = Path(__file__).with_name("perception_weights.pt")
DEFAULT_THRESHOLD = 0.35


class BevDetector(nn.Module):
    """The detector network; layer names are the tensor fault sites (`bev_grid.LAYER_SITES`)."""

    sites = LAYER_SITES  # the named layers `layers()` returns, in this order

    def __init__(self, widths: tuple[int, int, int] = (32, 48, 64), in_channels: int = CHANNELS,
                 classes: int = len(CLASSES)):
        """`classes`: class logits after the box channels of `head.box` (0: no class output,
        as weights trained before it)."""
        super().__init__()
        self.in_channels = in_channels  # the first grid channels it reads (weights before range/count: 6)
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
        self.head = nn.ModuleDict({"center": nn.Conv2d(c1, 1, 1), "box": nn.Conv2d(c1, BOX_CHANNELS + classes, 1)})
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
        return {name: named[name] for name in self.sites}

    def widen_input(self, channels: int = CHANNELS) -> None:
        """Read `channels` grid channels instead of fewer, computing the same function: the
        first layer's kernel gets zero weights for the new channels (a fine-tune from weights
        trained before the grid had them then learns what they add)."""
        old = self.backbone["conv0"]
        if old.in_channels >= channels:
            return
        new = nn.Conv2d(channels, old.out_channels, old.kernel_size, old.stride, old.padding).to(old.weight.device)
        with torch.no_grad():
            new.weight.zero_()
            new.weight[:, :old.in_channels] = old.weight
            new.bias.copy_(old.bias)
        self.backbone["conv0"] = new
        self.in_channels = channels


def boxes_to_world(boxes: np.ndarray, ego_pose, corrupt) -> list[Obj]:
    """A detector's (N, 7) vehicle-frame boxes (x, y, heading, length, width, confidence,
    class index into `bev_grid.CLASSES`) as objects in the world, the ego at `ego_pose`;
    `corrupt` sees each box's position first (the `perception.x`/`.y` fault sites)."""
    heading = ego_pose[2]
    objs = []
    for bx, by, bh, length, width, conf, cls in boxes.tolist():
        px = corrupt("perception.x", bx)
        py = corrupt("perception.y", by)
        objs.append(Obj(*vehicle_to_world(ego_pose, px, py), heading + bh, math.nan, math.nan, length, width, conf,
                        kind=CLASSES[int(cls)] if 0 <= cls < len(CLASSES) else ""))
    return objs


WEIGHTS_CACHE_SIZE = 4  # weight files kept per process (this detector's, the camera network's, a test's)
_WEIGHTS: LruCache[Path, tuple[dict, dict]] = LruCache(WEIGHTS_CACHE_SIZE)


def load_weights(path: Path = WEIGHTS_PATH) -> tuple[dict, dict]:
    """(state dict, metadata) from a weights file (this detector's or another's, e.g. the
    camera BEV network's), cached per process (read-only: copy it)."""
    path = Path(path)
    loaded = _WEIGHTS.get(path)
    if loaded is None:
        blob = torch.load(path, map_location="cpu", weights_only=True)
        loaded = (blob["state_dict"], blob.get("meta", {}))
        _WEIGHTS.put(path, loaded)
    return loaded


def load_model(path: Path = WEIGHTS_PATH, device: str = "cpu") -> tuple[BevDetector, dict]:
    """A fresh detector with the shipped weights: weight faults in one run touch only its copy."""
    state, meta = load_weights(path)
    model = BevDetector(tuple(meta["widths"]), in_channels=state["backbone.conv0.weight"].shape[1],
                        classes=len(meta.get("classes", ())))
    model.load_state_dict({k: v for k, v in state.items() if not k.startswith(cluster_class.PREFIX)})
    return model.to(device).eval(), meta


def load_cluster_classes(path: Path = WEIGHTS_PATH) -> tuple[TreeEnsemble, np.ndarray | None] | None:
    """The cluster class reader shipped with the weights (`cluster_class`) and its class
    logit offsets; None for weights without one (the class stays the CNN's at the peak)."""
    state, meta = load_weights(path)
    arrays = {k.removeprefix(cluster_class.PREFIX): v.numpy() for k, v in state.items()
              if k.startswith(cluster_class.PREFIX)}
    if not arrays:
        return None
    offsets = meta.get("cluster", {}).get("logit_offsets")
    return TreeEnsemble.from_state(arrays), None if offsets is None else np.asarray(offsets, dtype=np.float64)


Region = tuple[int, int, int, int]  # rows [r0, r1), columns [c0, c1) of a feature map
EMPTY: Region = (0, 0, 0, 0)
# A map's changed cells as boxes: the first is the points' region (one bounding box, as
# without faults; EMPTY for no points), any others are cells a fault hook changed away
# from it, kept apart while the cells they reach do not overlap (see RegionForward).
Regions = tuple[Region, ...]


def _union(a: Region, b: Region) -> Region:
    if a[0] >= a[1] or a[2] >= a[3]:
        return b
    if b[0] >= b[1] or b[2] >= b[3]:
        return a
    return (min(a[0], b[0]), max(a[1], b[1]), min(a[2], b[2]), max(a[3], b[3]))


def _overlap(a: Region, b: Region) -> bool:
    """Whether two boxes share a cell (an empty box shares none)."""
    return a[0] < b[1] and b[0] < a[1] and a[2] < b[3] and b[2] < a[3] and a[0] < a[1] and a[2] < a[3] \
        and b[0] < b[1] and b[2] < b[3]


def _merged(boxes: list[Region]) -> Regions:
    """Union overlapping boxes (into the earlier one) until none overlap; the first box
    keeps its place (empty or not), other empty boxes are dropped."""
    boxes = [boxes[0], *(b for b in boxes[1:] if not _empty(b))]
    i = 0
    while i < len(boxes):
        for j in range(i + 1, len(boxes)):
            if _overlap(boxes[i], boxes[j]):
                boxes[i] = _union(boxes[i], boxes.pop(j))
                i = -1  # a grown box may now meet an earlier one: look again from the start
                break
        i += 1
    return tuple(boxes)


def _changed(new: torch.Tensor, old: torch.Tensor) -> Region:
    """Bounding box of the elements a hook changed (NaN counts as changed)."""
    diff = (new != old).flatten(0, 1).any(dim=0)
    rows = torch.nonzero(diff.any(dim=1)).flatten()
    if len(rows) == 0:
        return EMPTY
    cols = torch.nonzero(diff.any(dim=0)).flatten()
    return (int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1)


def _cells(shape: tuple[int, ...], flat_indices: list[int]) -> Region:
    """Bounding box (rows, columns of the last two axes) of elements of a map by flat index."""
    if not flat_indices:
        return EMPTY
    h, w = shape[-2], shape[-1]
    rows = [(k // w) % h for k in flat_indices]
    cols = [k % w for k in flat_indices]
    return (min(rows), max(rows) + 1, min(cols), max(cols) + 1)


class _Views:
    """`t[:, :, r0:r1, c0:c1]` of tensors kept across frames, cached: a frame's regions are
    mostly the last frame's, and making a view costs about as much as a small kernel. An
    entry holds its tensor, so an id in a key is never another tensor's."""

    def __init__(self):
        self._cache: dict[tuple, tuple[torch.Tensor, torch.Tensor]] = {}

    def __call__(self, t: torch.Tensor, r0: int, r1: int, c0: int, c1: int) -> torch.Tensor:
        key = (id(t), r0, r1, c0, c1)
        hit = self._cache.get(key)
        if hit is not None and hit[0] is t:
            return hit[1]
        if len(self._cache) >= 256:  # regions wander over a run: start afresh now and then
            self._cache.clear()
        view = t[:, :, r0:r1, c0:c1]
        self._cache[key] = (t, view)
        return view


class _Map:
    """One feature map kept across inferences: equal to its background (the map for an
    empty grid) except inside `dirty`, so the next frame restores only that region."""

    __slots__ = ("background", "buf", "dirty", "views", "_nan_free")

    def __init__(self, background: torch.Tensor, views: _Views):
        self.background = background
        self.buf = background.clone()
        self.dirty: Regions = ()
        self.views = views
        self._nan_free: bool | None = None

    def equals(self, background: torch.Tensor) -> bool:
        """`torch.equal(self.background, background)`; for the same tensor (a rebuild that
        left this map as it was) that is whether it holds no NaN, found once."""
        if background is not self.background:
            return torch.equal(self.background, background)
        if self._nan_free is None:
            self._nan_free = torch.equal(background, background)
        return self._nan_free

    def restore(self, keep: Regions = ()) -> None:
        """Back to the background, except boxes inside `keep`, which the caller overwrites next."""
        for r0, r1, c0, c1 in self.dirty:
            if r0 >= r1 or c0 >= c1:
                continue
            for k in keep:
                if k[0] <= r0 and r1 <= k[1] and k[2] <= c0 and c1 <= k[3]:
                    break
            else:
                self.views(self.buf, r0, r1, c0, c1).copy_(self.views(self.background, r0, r1, c0, c1))
        self.dirty = ()

    def at(self, region: Region) -> torch.Tensor:
        """The buffer's view on `region` (to write the frame's values into)."""
        return self.views(self.buf, *region)


def _empty(region: Region) -> bool:
    return region[0] >= region[1] or region[2] >= region[3]


_INT_OF = {torch.float32: torch.int32, torch.float64: torch.int64, torch.float16: torch.int16,
           torch.bfloat16: torch.int16}


def _same_bits(a: tuple[torch.Tensor, ...], b: tuple[torch.Tensor, ...]) -> bool:
    """Tensors pairwise equal bit for bit (unlike torch.equal: -0.0 is not 0.0, a NaN is itself)."""
    return all(x.shape == y.shape and x.dtype == y.dtype and
               torch.equal(x.contiguous().view(_INT_OF[x.dtype]), y.contiguous().view(_INT_OF[y.dtype]))
               for x, y in zip(a, b, strict=True))


class RegionForward:
    """`BevDetector.forward` computed where the input differs from an empty grid.

    A scan fills ~1 % of the grid; away from the points every layer's output is what it
    is for an empty grid (the *background*, computed once per weights). So each conv is
    evaluated only on the output cells whose window meets its input's changed region
    (a bounding box that grows by the kernel's reach per layer), and every map is kept
    between frames as its background plus the last frame's region, which is restored
    first: the work per frame follows the occupied area, not the grid.
    Same arithmetic as the dense forward up to float rounding (a conv on a smaller
    window may sum in another order); deterministic for a given input.

    Hooks on a layer (tensor faults) see and may change its whole output as in the
    dense forward: forward pre-hooks run before the layer (a weight flip there makes the
    backgrounds stale: they are rebuilt), forward hooks get the full pre-activation
    output, and the bounding box of what they change is followed as a box of its own
    (`Regions`): each later layer computes it apart from the points' box unless the
    cells the two reach overlap (then on their union), and after each ReLU it is dropped
    if it is back to the background bit for bit (a flip the ReLU undoes stops there).
    So a flip costs about its own reach, not the bounding box of it and the points, and
    the points' box gets the windows of a run without faults. Fault hooks that offer
    `flip_owned` flip the kept map in place and report the flipped elements; any other
    hook's changes are found by comparing the map with a copy taken before it ran.
    """

    def __init__(self, model: BevDetector):
        self.model = model
        self.layers = model.layers()
        self.maps: dict[str, _Map] | None = None
        self._snapshot: dict[str, tuple[torch.Tensor, torch.Tensor]] = {}
        self._last_backgrounds: dict[str, torch.Tensor] = {}  # the last rebuild's maps, as computed
        self.views = _Views()
        # Per layer (kernel, stride, padding, weight, bias): read once, not through
        # nn.Module's attribute lookup at every call (faults flip the tensors in place).
        self._geometry: dict[str, tuple] = {}

    def invalidate(self) -> None:
        """Weights changed: rebuild the backgrounds at the next inference."""
        self.maps = None

    def __call__(self, x: torch.Tensor, region: Region) -> tuple[torch.Tensor, torch.Tensor]:
        """Head outputs (heat, box) for grid `x`, which is zero outside `region`.

        The returned tensors are reused by the next call: copy what must outlive it.
        """
        if self.maps is None:
            self._rebuild()
        return self._forward(x, region)

    # ---- backgrounds
    # The dense network for an empty grid, as (map, layer, inputs): a map is its layer's
    # conv of its one input ("conv"), the ReLU of a conv's map ("relu") or a nearest x2
    # upsampling of its first input plus its second ("up_add").
    _GRAPH = (
        ("backbone.conv0", "conv", ("grid",)), ("x0", "relu", ("backbone.conv0",)),
        ("backbone.conv1", "conv", ("x0",)), ("x1", "relu", ("backbone.conv1",)),
        ("backbone.conv2", "conv", ("x1",)), ("x2", "relu", ("backbone.conv2",)),
        ("backbone.conv3", "conv", ("x2",)), ("x3", "relu", ("backbone.conv3",)),
        ("neck.lateral", "conv", ("x3",)), ("u", "up_add", ("neck.lateral", "x1")),
        ("neck.fuse", "conv", ("u",)), ("f", "relu", ("neck.fuse",)),
        ("neck.lateral_fine", "conv", ("f",)), ("v", "up_add", ("neck.lateral_fine", "x0")),
        ("neck.fine", "conv", ("v",)), ("g", "relu", ("neck.fine",)),
        ("head.center", "conv", ("g",)), ("head.box", "conv", ("g",)),
    )

    def _rebuild(self) -> None:
        """Backgrounds of every map (dense, no hooks) from the current weights. Maps whose
        background did not change keep their state (a rebuild may happen mid-inference).

        After a weight fault, a map is computed again only if its layer's weights or one
        of its inputs differ bit for bit from the last rebuild's; otherwise the dense
        computation, which is deterministic, would give the last rebuild's tensor again,
        and that is taken. So only the layers from the flipped one on are recomputed, and
        less where a map comes out as before (a flipped kernel weight of the first layer
        meets only zeros)."""
        rebuilt = self.maps is not None
        last, old_snapshot = (self._last_backgrounds, self._snapshot) if rebuilt else ({}, {})
        self._snapshot = {n: (m.weight.detach().clone(), m.bias.detach().clone()) for n, m in self.layers.items()}
        self._geometry = {n: (m.kernel_size[0], m.stride[0], m.padding[0], m.weight, m.bias)
                          for n, m in self.layers.items()}
        weight = self.layers["backbone.conv0"].weight
        bg: dict[str, torch.Tensor] = {"grid": torch.zeros((1, weight.shape[1], GRID.nx, GRID.ny), dtype=weight.dtype,
                                                           device=weight.device)}
        changed: set[str] = set()  # maps that differ bit for bit from the last rebuild's
        for name, op, inputs in self._GRAPH:
            if name in last and not changed.intersection(inputs) and \
                    (op != "conv" or _same_bits(self._snapshot[name], old_snapshot[name])):
                bg[name] = last[name]
                continue
            if op == "conv":
                layer = self.layers[name]
                t = F.conv2d(bg[inputs[0]], layer.weight, layer.bias, layer.stride, layer.padding)
            elif op == "relu":
                t = F.relu(bg[inputs[0]])
            else:
                t = F.interpolate(bg[inputs[0]], scale_factor=2.0, mode="nearest") + bg[inputs[1]]
            if name in last and _same_bits((t,), (last[name],)):
                bg[name] = last[name]  # the same bits: keep the tensor (and the maps that hold it)
            else:
                bg[name] = t
                changed.add(name)
        del bg["grid"]
        self._last_backgrounds = bg
        old = self.maps or {}
        self.maps = {k: old[k] if k in old and old[k].equals(t) else _Map(t, self.views) for k, t in bg.items()}

    def _weights_changed(self, name: str) -> bool:
        layer = self.layers[name]
        w, b = self._snapshot[name]
        return not (torch.equal(layer.weight, w) and torch.equal(layer.bias, b))

    # ---- the layers on regions
    def _conv(self, name: str, x: torch.Tensor, regions: Regions) -> tuple[torch.Tensor, Regions]:
        layer = self.layers[name]
        if layer._forward_pre_hooks:
            for hook in list(layer._forward_pre_hooks.values()):
                hook(layer, (x,))
            if self._weights_changed(name):  # a persistent weight fault
                self._rebuild()
        out = self.maps[name]
        computed = self._windows(name, x, regions, out.buf.shape)
        cells = tuple(c for c, _ in computed)
        out.restore(cells)
        for c, result in computed:
            if result is not None:
                out.at(c).copy_(result)
        out.dirty = cells
        if layer._forward_hooks:
            flipped = self._hooked(layer, x, out.buf)
            if not _empty(flipped):
                out.dirty = _merged([*out.dirty, flipped])
        return out.buf, out.dirty

    def _conv_relu(self, name: str, relu: str, x: torch.Tensor, regions: Regions) -> tuple[torch.Tensor, Regions]:
        """`_relu(relu, *_conv(name, ...))`: with no hook on the layer, the ReLU is taken
        straight from the conv's windows (same values), and the pre-activation map, which
        only hooks read, is left at its background."""
        layer = self.layers[name]
        if layer._forward_pre_hooks or layer._forward_hooks:
            a, r = self._conv(name, x, regions)
            return self._relu(relu, a, r), self._shrunk(relu, r)
        self.maps[name].restore()  # after a hooked frame: back to the background once
        computed = self._windows(name, x, regions, self.maps[name].buf.shape)
        cells = tuple(c for c, _ in computed)
        out = self.maps[relu]
        out.restore(cells)
        for c, result in computed:
            if result is not None:
                torch.clamp_min(result, 0.0, out=out.at(c))
        out.dirty = cells
        return out.buf, self._shrunk(relu, cells) if len(cells) > 1 else cells

    def _shrunk(self, name: str, regions: Regions) -> Regions:
        """A fault's boxes (all but the first) without those whose cells in map `name` are
        all back to its background bit for bit: a flip the ReLU undoes (a negative value
        that stays negative) stops there instead of widening every later layer. (One
        comparison per box: cutting a box to its changed cells costs more than it saves,
        as a live flip changes its whole reach.) The map still restores the cells it
        wrote (`dirty`). The points' box is kept as it is, so a run without faults
        computes the windows it always did."""
        if len(regions) == 1:
            return regions
        m = self.maps[name]
        bits = _INT_OF[m.buf.dtype]
        return (regions[0], *(box for box in regions[1:]
                              if not torch.equal(m.at(box).view(bits), self.views(m.background, *box).view(bits))))

    def _windows(self, name: str, x: torch.Tensor, regions: Regions, shape) -> list[tuple[Region, torch.Tensor | None]]:
        """`_window` for each box of `regions`; boxes whose output cells would overlap are
        joined first (a cell's window must see every change around it), so each output
        cell is computed once. The first box's windows are those of the points' region
        alone (what a run without faults computes)."""
        if len(regions) > 1:
            boxes = list(regions)
            i = 0
            while i < len(boxes):
                ci = self._cells_of(name, boxes[i], shape)
                for j in range(i + 1, len(boxes)):
                    if _overlap(ci, self._cells_of(name, boxes[j], shape)):
                        boxes[i] = _union(boxes[i], boxes.pop(j))
                        i = -1  # look again from the start
                        break
                i += 1
            return [self._window(name, x, r, shape) for r in boxes]
        return [self._window(name, x, regions[0], shape)]

    def _cells_of(self, name: str, region: Region, shape) -> Region:
        """The output cells of layer `name` whose window meets `region` (as `_window`)."""
        r0, r1, c0, c1 = region
        if r0 >= r1 or c0 >= c1:
            return EMPTY
        k, s, p = self._geometry[name][:3]
        _, _, h_out, w_out = shape
        return (max(0, -(-(r0 + p - k + 1) // s)), min(h_out, (r1 - 1 + p) // s + 1),
                max(0, -(-(c0 + p - k + 1) // s)), min(w_out, (c1 - 1 + p) // s + 1))

    def _window(self, name: str, x: torch.Tensor, region: Region, shape) -> tuple[Region, torch.Tensor | None]:
        """The output cells of layer `name` whose k×k window (stride s, padding p) meets the
        changed input `region`, and the conv on them (EMPTY, None for an empty region)."""
        r0, r1, c0, c1 = region
        if r0 >= r1 or c0 >= c1:
            return EMPTY, None
        k, s, p, weight, bias = self._geometry[name]
        _, _, h_in, w_in = x.shape
        _, _, h_out, w_out = shape
        o0, o1 = max(0, -(-(r0 + p - k + 1) // s)), min(h_out, (r1 - 1 + p) // s + 1)
        q0, q1 = max(0, -(-(c0 + p - k + 1) // s)), min(w_out, (c1 - 1 + p) // s + 1)
        i0, i1 = s * o0 - p, s * (o1 - 1) - p + k
        j0, j1 = s * q0 - p, s * (q1 - 1) - p + k
        window = self.views(x, max(i0, 0), min(i1, h_in), max(j0, 0), min(j1, w_in))
        if i0 < 0 or j0 < 0 or i1 > h_in or j1 > w_in:  # zero padding only where the window crosses the border
            window = F.pad(window, (max(0, -j0), max(0, j1 - w_in), max(0, -i0), max(0, i1 - h_in)))
        return (o0, o1, q0, q1), F.conv2d(window, weight, bias, s)

    @staticmethod
    def _hooked(layer: nn.Conv2d, x: torch.Tensor, buf: torch.Tensor) -> Region:
        """Run `layer`'s forward hooks on its output map `buf`; the region they changed."""
        hooks = list(layer._forward_hooks.values())
        owned = [getattr(hook, "flip_owned", None) for hook in hooks]
        if all(owned):
            # Fault hooks (runtime.faults.tensor, tensorfaults.ActivationFlip) flip `buf` in
            # place and say what they flipped: the changed cells are those elements whose
            # last value differs from their first (a NaN counts as changed), exactly what
            # comparing the whole map with a clone would find, at the cost of the flips.
            first: dict[int, float] = {}
            last: dict[int, float] = {}
            for flip in owned:
                for k, before, after in flip(buf):
                    first.setdefault(k, before)
                    last[k] = after
            return _cells(buf.shape, [k for k, after in last.items() if after != first[k]])
        before = buf.clone()  # any other hook: find what it changed by comparison
        for hook in hooks:
            result = hook(layer, (x,), buf)
            if result is not None and result is not buf:
                buf.copy_(result)
        return _changed(buf, before)

    def _relu(self, name: str, x: torch.Tensor, regions: Regions) -> torch.Tensor:
        out = self.maps[name]
        out.restore(regions)
        for r0, r1, c0, c1 in regions:
            if r0 < r1 and c0 < c1:
                torch.clamp_min(self.views(x, r0, r1, c0, c1), 0.0, out=out.at((r0, r1, c0, c1)))
        out.dirty = regions
        return out.buf

    def _up_add(self, name: str, low: torch.Tensor, low_regions: Regions, skip: torch.Tensor,
                skip_regions: Regions) -> tuple[torch.Tensor, Regions]:
        """Nearest ×2 upsampling of `low` plus `skip`, on their changed regions: the first
        boxes' union, and the other boxes apart from it (joined where they overlap)."""
        out = self.maps[name]
        lr0, lr1, lc0, lc1 = low_regions[0]
        regions: Regions = (_union((2 * lr0, 2 * lr1, 2 * lc0, 2 * lc1), skip_regions[0]),)
        if len(low_regions) > 1 or len(skip_regions) > 1:
            regions = _merged([*regions, *((2 * a, 2 * b, 2 * c, 2 * d) for a, b, c, d in low_regions[1:]),
                               *skip_regions[1:]])
        out.restore(regions)
        for region in regions:
            if _empty(region):
                continue
            r0, r1, c0, c1 = region
            low_v = self.views(low, r0 // 2, (r1 + 1) // 2, c0 // 2, (c1 + 1) // 2)
            # Nearest ×2 copies values: any way of doing it gives the same bits; interpolate
            # is the quickest here (an expand + reshape copy costs ~1.3x on these windows).
            up = F.interpolate(low_v, scale_factor=2.0, mode="nearest")
            dr, dc = r0 - 2 * (r0 // 2), c0 - 2 * (c0 // 2)
            torch.add(up[:, :, dr:dr + r1 - r0, dc:dc + c1 - c0], self.views(skip, r0, r1, c0, c1),
                      out=out.at(region))
        out.dirty = regions
        return out.buf, regions

    def _forward(self, x: torch.Tensor, region: Region) -> tuple[torch.Tensor, torch.Tensor]:
        """The network of `BevDetector.forward`, layer by layer on changed regions."""
        x0, r0 = self._conv_relu("backbone.conv0", "x0", x, (region,))
        x1, r1 = self._conv_relu("backbone.conv1", "x1", x0, r0)
        a, r = self._conv_relu("backbone.conv2", "x2", x1, r1)
        a, r = self._conv_relu("backbone.conv3", "x3", a, r)
        a, r = self._conv("neck.lateral", a, r)
        u, r = self._up_add("u", a, r, x1, r1)
        a, r = self._conv_relu("neck.fuse", "f", u, r)
        a, r = self._conv("neck.lateral_fine", a, r)
        v, r = self._up_add("v", a, r, x0, r0)
        g, r = self._conv_relu("neck.fine", "g", v, r)
        heat, _ = self._conv("head.center", g, r)
        box, _ = self._conv("head.box", g, r)
        return heat, box


@contextmanager
def _one_intra_op_thread():
    """One torch intra-op thread for an inference: results must not depend on the
    machine's core count (a conv's partial sums split by thread), and the tiny network
    gains nothing from threads but jitter and contention with parallel runs. Scoped to
    the call (toggling costs ~5 us), so a process that embeds the runtime keeps its own
    setting; worker processes that already run one thread pay nothing."""
    previous = torch.get_num_threads()
    if previous == 1:
        yield
        return
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(previous)


one_intra_op_thread = _one_intra_op_thread  # public: the camera BEV node runs under it too


class LearnedPerception(ConvTensorSites):
    """The `perception learned` node: lidar frame → grid → CNN → objects in world coordinates."""

    name = "perception"
    sites = ("perception.x", "perception.y")
    tensor_sites = tuple(f"perception.{n}" for n in LAYER_SITES)

    def __init__(self, settings: dict, ctx=None, weights: Path = WEIGHTS_PATH, device: str = "cpu"):
        self.model, self.meta = load_model(weights, device)
        self.cluster_classes = load_cluster_classes(weights)
        self.device = device
        self.threshold = float(settings.get("detect_threshold", self.meta.get("threshold", DEFAULT_THRESHOLD)))
        self._logit_threshold = math.log(self.threshold / (1.0 - self.threshold))
        self._grid = np.zeros(GRID.shape, dtype=np.float32)
        self._grid_region: tuple[int, int, int, int] | None = None  # None: clear the whole grid
        # Shares memory with the grid buffer; the channels the weights read (a leading slice: contiguous).
        self._input = torch.from_numpy(self._grid)[None, :self.model.in_channels]
        # On another device, one input tensor kept there (RegionForward's views of it stay valid).
        self._device_input = self._input if device == "cpu" else torch.empty_like(self._input, device=device)
        self._layers = self.model.layers()
        self._shapes: dict[str, tuple[int, ...]] | None = None
        self._forward = RegionForward(self.model)
        self._armed: list[ActivationFlip] = []
        self.last_activation_flips: list[tuple[str, tuple]] = []
        # Warm-up: the first inference pays one-off kernel set-up, which would otherwise
        # show as a latency spike in the first frame of `latency measured` runs.
        self.detect(np.zeros((0, 3)), (0.0, 0.0))

    # ---- the node
    def run(self, frame, sensor, ego_pose, corrupt) -> list[Obj]:
        points = frame.data["points"]
        nominal = sensor.nominal
        pts = sensor_points_to_vehicle(points, nominal) if len(points) else np.zeros((0, 3))
        boxes = self.detect(pts, (nominal.x, nominal.y))
        return boxes_to_world(boxes, ego_pose, corrupt)

    def detect(self, points_vehicle: np.ndarray, sensor_xy: tuple[float, float]) -> np.ndarray:
        """Vehicle-frame points → (N, 7) boxes: x, y, heading, length, width, confidence,
        class (index into `bev_grid.CLASSES`)."""
        found, box = self.detect_raw(points_vehicle, sensor_xy)
        if len(found) and self.cluster_classes is not None:
            cluster_class.reclass(found, points_vehicle, sensor_xy, box, *self.cluster_classes)
        return found

    def detect_raw(self, points_vehicle: np.ndarray, sensor_xy: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
        """`detect` with the CNN's class at the peak, and its `head.box` map (a view of a
        buffer the next inference overwrites): what the cluster class reader reads."""
        # The grid is zero outside the last frame's region: clear only that.
        _, region = build_grid_region(points_vehicle, sensor_xy, out=self._grid, dirty=self._grid_region)
        self._grid_region = region
        with torch.inference_mode(), _one_intra_op_thread():
            x = self._input if self.device == "cpu" else self._device_input.copy_(self._input)
            heat, box = self._forward(x, region)
            heat, box = heat[0, 0].cpu().numpy(), box[0].cpu().numpy()
        self._collect_fired()
        # Threshold on logits (monotone): the sigmoid is only needed at the peaks.
        found = decode(heat, box, self._logit_threshold)
        if len(found):
            with np.errstate(over="ignore"):
                found[:, 5] = 1.0 / (1.0 + exp.over(-found[:, 5]))
        return found, box

    # ---- tensor fault sites
    def activation_shape(self, site: str) -> tuple[int, ...]:
        self._layer(site)
        if self._shapes is None:  # once per node: the lookup walks the model's modules (~50 us)
            self._shapes = _activation_shapes(self.model, self.device)
        return self._shapes[site.removeprefix("perception.")]

    def _after_weight_flip(self) -> None:
        self._forward.invalidate()  # the backgrounds came from the old weights


SHAPES_CACHE_SIZE = 16  # (device, layer widths) -> shapes: a few models per process
_SHAPES: LruCache[tuple, dict[str, tuple[int, ...]]] = LruCache(SHAPES_CACHE_SIZE)


def _activation_shapes(model: BevDetector, device: str) -> dict[str, tuple[int, ...]]:
    """Output shape of every named layer at batch 1 (one dry run, cached per device and widths)."""
    key = (device, model.in_channels, tuple(layer.out_channels for layer in model.layers().values()))
    shapes = _SHAPES.get(key)
    if shapes is None:
        shapes = {}
        hooks = [layer.register_forward_hook(
            lambda m, i, o, name=name: shapes.__setitem__(name, tuple(o.shape)))
            for name, layer in model.layers().items()]
        with torch.inference_mode():
            model(torch.zeros((1, model.in_channels, GRID.nx, GRID.ny), device=device))
        for h in hooks:
            h.remove()
        _SHAPES.put(key, shapes)
    return shapes
