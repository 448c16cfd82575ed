"""Bit flips in torch tensors: the low-level utilities behind the detector's tensor fault sites.

Pure torch; works on CPU and CUDA tensors alike (the flip is an integer XOR on the
tensor's bits, done where the tensor lives).

- `flip_bits(tensor, flat_indices, bits)` flips bit `bits[k]` of element
  `flat_indices[k]` in place (float32: bit 0 is the lowest mantissa bit, 31 the sign)
  and returns the values before and after.
- `bit_field(name)` is the bit range of an IEEE-754 float32 field (`sign`, `exponent`,
  `mantissa`, `any`), for drawing a random bit from it.
- `ActivationFlip(module, flat_indices, bits)` is a context manager that flips bits in
  the module's output for a single forward call (a transient fault: one inference),
  then removes itself.

Weight flips are persistent: flip a parameter's `.data` with `flip_bits`; flipping the
same bit again restores it exactly.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch

FLOAT32_FIELDS = {"sign": (31, 32), "exponent": (23, 31), "mantissa": (0, 23), "any": (0, 32)}
_INT_VIEW = {torch.float32: torch.int32, torch.float16: torch.int16, torch.bfloat16: torch.int16,
             torch.float64: torch.int64}


def bit_field(name: str, dtype: torch.dtype = torch.float32) -> tuple[int, int]:
    """[low, high) bit range of an IEEE-754 field (float32 only)."""
    if dtype != torch.float32:
        raise ValueError(f"IEEE-754 fields are defined here for float32, not {dtype}")
    try:
        return FLOAT32_FIELDS[name]
    except KeyError:
        raise ValueError(f"unknown bit field {name!r}; choose from {', '.join(FLOAT32_FIELDS)}") from None


def flip_bits(tensor: torch.Tensor, flat_indices: Sequence[int], bits: Sequence[int]):
    """Flip `bits[k]` of element `flat_indices[k]` of `tensor`, in place.

    Returns (before, after): float lists of the touched elements' values. The same
    index may appear twice (its flips compose). Raises on an out-of-range index or bit.
    """
    if tensor.dtype not in _INT_VIEW:
        raise TypeError(f"cannot flip bits of a {tensor.dtype} tensor")
    if len(flat_indices) != len(bits):
        raise ValueError("flat_indices and bits must have the same length")
    if not tensor.is_contiguous():
        raise ValueError("flip_bits needs a contiguous tensor")
    width = tensor.element_size() * 8
    n = tensor.numel()
    for i, b in zip(flat_indices, bits):
        if not 0 <= int(i) < n:
            raise IndexError(f"element {i} out of range for a tensor of {n} elements")
        if not 0 <= int(b) < width:
            raise ValueError(f"bit {b} out of range for {width}-bit elements")
    flat = tensor.detach().view(-1)
    ints = flat.view(_INT_VIEW[tensor.dtype])
    idx = torch.as_tensor([int(i) for i in flat_indices], dtype=torch.long, device=tensor.device)
    # 1 << 31 does not fit a signed int32: build the masks in int64 and wrap them.
    masks64 = torch.as_tensor([1 << int(b) for b in bits], dtype=torch.int64)
    masks64 = torch.where(masks64 >= 2 ** (width - 1), masks64 - 2 ** width, masks64)
    masks = masks64.to(ints.dtype).to(tensor.device)
    before = flat[idx].tolist()
    with torch.no_grad():
        for k in range(len(idx)):  # sequential so a repeated index composes
            ints[idx[k]] ^= masks[k]
    after = flat[idx].tolist()
    return before, after


class ActivationFlip:
    """Flip bits in `module`'s output on its next forward call only (a transient fault).

    Use as a context manager around one inference, or call `arm()` and let the hook
    remove itself after firing. `fired` holds (before, after) once it has run. Indices
    are into the flattened output (batch included).
    """

    def __init__(self, module: torch.nn.Module, flat_indices: Sequence[int], bits: Sequence[int]):
        self.module = module
        self.flat_indices = [int(i) for i in flat_indices]
        self.bits = [int(b) for b in bits]
        self.fired: tuple[list[float], list[float]] | None = None
        self._handle = None

    def arm(self) -> ActivationFlip:
        self._handle = self.module.register_forward_hook(self._hook)
        return self

    def disarm(self) -> None:
        if self._handle is not None:
            self._handle.remove()
            self._handle = None

    def _hook(self, module, inputs, output):
        # The output is a fresh tensor every call, so flipping it in place is transient.
        out = output.contiguous()
        self.fired = flip_bits(out, self.flat_indices, self.bits)
        self.disarm()
        return out

    def flip_owned(self, output: torch.Tensor) -> list[tuple[int, float, float]]:
        """Flip in place an output map the caller owns and restores itself (the
        detector's `RegionForward`); (flat index, before, after) per flip."""
        self.fired = flip_bits(output, self.flat_indices, self.bits)
        self.disarm()
        return list(zip(self.flat_indices, *self.fired))

    def __enter__(self) -> ActivationFlip:
        return self.arm()

    def __exit__(self, *exc) -> None:
        self.disarm()


class ConvTensorSites:
    """The tensor fault sites of a perception node whose network is named conv layers
    (`learned`, `camera_bev`): site `perception.NAME` is layer NAME; its *weights* are the
    kernel followed by the bias in one flat index space, its *activations* the layer's
    output for one frame.

    The node provides `tensor_sites`, `_layers` (name → conv layer), `_armed` (a list) and
    `activation_shape(site)`; `_after_weight_flip()` is called once a weight flip is done
    (a node that keeps results computed from its weights drops them there).
    """

    tensor_sites: tuple[str, ...] = ()

    def fault_sites(self) -> tuple[str, ...]:
        return self.tensor_sites

    def tensor_modules(self) -> dict:
        """Site name → torch module, for the fault engine's `bitflip ... tensor` hooks."""
        return {f"perception.{name}": layer for name, layer in self._layers.items()}

    def _layer(self, site: str):
        name = site.removeprefix("perception.")
        if name not in self._layers:
            raise KeyError(f"unknown tensor site {site!r}; sites: {', '.join(self.tensor_sites)}")
        return self._layers[name]

    def activation_shape(self, site: str) -> tuple[int, ...]:
        raise NotImplementedError

    def site_numel(self, site: str, tensor: str = "weights") -> int:
        """Elements addressable at a site: kernel + bias (weights) or the output of one frame."""
        layer = self._layer(site)
        if tensor == "weights":
            return layer.weight.numel() + (layer.bias.numel() if layer.bias is not None else 0)
        if tensor == "activations":
            return math.prod(self.activation_shape(site))
        raise ValueError(f"tensor must be 'weights' or 'activations', not {tensor!r}")

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
        self._after_weight_flip()
        return before, after

    def _after_weight_flip(self) -> None:
        pass

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
