"""Bit flips in torch tensors: weights (persistent) and activations (one inference).

The interface a stack offers for tensor faults is one method:

    stack.tensor_sites() -> Mapping[str, torch.nn.Module]

naming each injectable layer in DSL form (`perception.backbone_0.conv`, see
`tensor_site_name`). Nothing else is needed from the stack: the fault attaches a
forward hook to the named module at each flip instant (a schedule timer) and removes
it once the forward pass has taken the flip, so outside its flips a model runs with no
hook at all, and

- `tensor weights`: at each flip instant, the next forward pass of the layer first
  flips one bit of one element of its parameters (weights and biases, recursively,
  an element drawn uniformly over all of them). The flip stays for the rest of the
  run (a memory fault); `close()` restores the original bits at the end of the run,
  so a model cached across runs is clean again.
- `tensor activations`: at each flip instant, the next forward pass of the layer
  has one bit of one element of its output flipped, for that inference only (a
  datapath/register fault).

A stack that keeps a layer's output map itself and restores it between inferences
may call the activation hook's `flip_owned(map)` instead of running it as a torch hook
(`addt_dsl.stack.learned.RegionForward` does): the flips land in place and come back as
(flat index, before, after), so the caller knows what changed without comparing maps.

Works on CPU and CUDA tensors of dtype float16, bfloat16, float32 and float64: the
tensor is reinterpreted as integers of the same width and the bit XORed in place.
torch is imported only when a tensor fault is bound.
"""

from __future__ import annotations

from collections.abc import Mapping

from addt_dsl.runtime.faults.base import IEEE_FIELDS, IEEE_FIELDS_BF16


def tensor_site_name(prefix: str, module_name: str) -> str:
    """DSL name of a torch module: numeric path parts join their parent with `_`.

    `tensor_site_name("perception", "backbone.0.conv")` → `perception.backbone_0.conv`,
    `tensor_site_name("perception", "0")` → `perception_0` (a target in `.addt` is a
    dotted path of names, and a name cannot start with a digit).
    """
    out = prefix
    for part in filter(None, module_name.split(".")):
        out += f"_{part}" if part.isdigit() else f".{part}"
    return out


def tensor_sites_of(model, prefix: str) -> dict[str, object]:
    """Every named submodule of `model` as a tensor site (`prefix` is the whole model)."""
    return {tensor_site_name(prefix, name): module for name, module in model.named_modules()}


def _int_dtype(torch, dtype):
    return {torch.float64: torch.int64, torch.float32: torch.int32,
            torch.float16: torch.int16, torch.bfloat16: torch.int16}.get(dtype)


def bit_range(dtype, field: str) -> tuple[int, int]:
    """[lo, hi) of the bits of `field` (sign, exponent, mantissa, any) for a float dtype."""
    import torch

    if dtype == torch.bfloat16:
        return IEEE_FIELDS_BF16[field]
    width = torch.finfo(dtype).bits
    return IEEE_FIELDS[width][field]


def _numpy_int(torch, np, dtype):
    """The numpy integer type of a torch float dtype's width (None for bfloat16: numpy has none)."""
    return {torch.float64: np.int64, torch.float32: np.int32, torch.float16: np.int16}.get(dtype)


def flip_bit_(tensor, flat_index: int, bit: int) -> tuple[float, float]:
    """Flip bit `bit` of element `flat_index` (row-major) of `tensor`, in place.

    Returns the element's value before and after. Works for any strides and device.
    """
    import numpy as np
    import torch

    itype = _int_dtype(torch, tensor.dtype)
    if itype is None:
        raise TypeError(f"bit flips need a floating-point tensor, not {tensor.dtype}")
    width = torch.iinfo(itype).bits
    if not 0 <= bit < width:
        raise ValueError(f"bit {bit} is outside a {width}-bit {tensor.dtype} element")
    mask = 1 << bit
    if mask >= 1 << (width - 1):  # the sign bit, as the signed integer it is stored as
        mask -= 1 << width
    numpy_int = _numpy_int(torch, np, tensor.dtype)
    if numpy_int is not None and tensor.device.type == "cpu" and tensor.is_contiguous():
        # The same element and XOR through a numpy view of the memory: a few us, where the
        # torch indexing below costs ~40 us a flip (10 flips a second add up in a sweep).
        floats = tensor.detach().numpy().reshape(-1)
        ints = floats.view(numpy_int)
        k = int(flat_index)
        if not 0 <= k < len(ints):  # as np.unravel_index below
            raise ValueError(f"index {k} is out of bounds for array with size {len(ints)}")
        before = float(floats[k])
        ints[k] ^= numpy_int(mask)
        return before, float(floats[k])
    index = tuple(int(i) for i in np.unravel_index(int(flat_index), tuple(tensor.shape)))
    with torch.no_grad():
        ints = tensor.view(itype)
        before = float(tensor[index].item())
        ints[index] = ints[index] ^ mask
        after = float(tensor[index].item())
    return before, after


class TensorFlipper:
    """Applies one `bitflip` fault to one torch module through forward hooks.

    A hook is attached only while a flip is pending: from the flip's instant (a timer,
    `Binding.at`) to the forward pass that takes it, then removed until the next
    instant, so a model runs hook-free outside the fault's flips.

    Activations: the forward hook flips a clone of the layer's output and returns it
    (a layer may return a buffer it keeps). A caller that owns the output map and
    restores it itself (the detector's `RegionForward`) calls `flip_owned` instead, which
    flips in place and returns what it flipped: no clone, no comparison of maps.
    """

    def __init__(self, fault, site: str, module, mode: str, at=lambda time_s, callback: callback()):
        self.fault = fault  # the BitFlip fault kind: instants, rng, bit choice, record
        self.site = site
        self.module = module
        self.mode = mode
        self.applied: list[tuple[object, int, int]] = []  # (tensor, flat index, bit) to undo
        self.handle = None
        self._at = at
        if mode == "weights":
            self.params = [(n, p) for n, p in module.named_parameters() if p.is_floating_point()]
            if not self.params:
                raise ValueError(f"tensor site '{site}' has no floating-point weights to flip")
        self.arm_next()

    # ---- attaching the hook while a flip is pending
    def arm_next(self) -> None:
        if self.fault.pending():
            self._at(self.fault.next_time(), self.arm)

    def arm(self) -> None:
        if self.handle is None:
            self.handle = (self.module.register_forward_pre_hook(self._pre_hook) if self.mode == "weights"
                           else self.module.register_forward_hook(self))

    def disarm(self) -> None:
        if self.handle is not None:
            self.handle.remove()
            self.handle = None

    def _taken(self) -> None:
        """The due flips are done: detach until the next instant."""
        self.disarm()
        self.arm_next()

    # ---- weights
    def _pre_hook(self, module, inputs):
        n = self.fault.due()
        for _ in range(n):
            total = sum(p.numel() for _, p in self.params)
            k = int(self.fault.rng.integers(total))
            for name, p in self.params:
                if k < p.numel():
                    break
                k -= p.numel()
            bit = self.fault.bit_for(p.dtype)
            before, after = flip_bit_(p.data, k, bit)
            self.applied.append((p.data, k, bit))
            self.fault.record(self.fault.clock(), f"{self.site}:{name}[{k}]", after, bit=bit, before=before,
                              tensor="weights", device=str(p.device), dtype=str(p.dtype).replace("torch.", ""))
        if n:
            self._taken()

    # ---- activations
    def _flip(self, tensor, n: int) -> list[tuple[int, float, float]]:
        flips = []
        for _ in range(n):
            k = int(self.fault.rng.integers(tensor.numel()))
            bit = self.fault.bit_for(tensor.dtype)
            before, after = flip_bit_(tensor, k, bit)
            flips.append((k, before, after))
            self.fault.record(self.fault.clock(), f"{self.site}:output[{k}]", after, bit=bit, before=before,
                              tensor="activations", device=str(tensor.device),
                              dtype=str(tensor.dtype).replace("torch.", ""))
        self._taken()
        return flips

    def flip_owned(self, tensor) -> list[tuple[int, float, float]]:
        """Flip the due elements of an output map the caller owns, in place.

        Returns (flat index, value before, value after) per flip, in order (an element
        flipped twice appears twice); empty when no flip is due. Draws and records
        exactly as the forward hook does on the same map.
        """
        n = self.fault.due()
        if n == 0:
            return []
        if not tensor.is_floating_point():
            raise TypeError(f"tensor site '{self.site}' has no floating-point output to flip")
        return self._flip(tensor, n)

    def __call__(self, module, inputs, output):
        """The forward hook (activations): the output with the due flips, on a clone."""
        n = self.fault.due()
        if n == 0:
            return None
        import torch

        out = output
        tensor = out if isinstance(out, torch.Tensor) else next(
            (o for o in (out.values() if isinstance(out, Mapping) else out) if isinstance(o, torch.Tensor)), None)
        if tensor is None or not tensor.is_floating_point():
            raise TypeError(f"tensor site '{self.site}' has no floating-point output to flip")
        flipped = tensor.clone()  # the flip is transient: never write into a buffer the layer keeps
        self._flip(flipped, n)
        if isinstance(out, torch.Tensor):
            return flipped
        if isinstance(out, Mapping):
            return type(out)({k: (flipped if v is tensor else v) for k, v in out.items()})
        return type(out)(flipped if o is tensor else o for o in out)

    def close(self) -> None:
        self.disarm()
        # Undo weight flips in reverse order: the model is bit-identical to before the run.
        for tensor, k, bit in reversed(self.applied):
            flip_bit_(tensor, k, bit)
        self.applied.clear()
