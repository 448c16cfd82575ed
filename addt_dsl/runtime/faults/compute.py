"""Compute faults: bit flips, stuck-at and random values in the stack's variables and tensors."""

from __future__ import annotations

import math

import numpy as np

from addt_dsl.registry import FAULTS
from addt_dsl.specs import faults as S
from addt_dsl.runtime.faults.base import (BIT_FIELDS_F64, Binding, FaultKind, flip_float64_bit,
                                          flip_stored_bit)


@FAULTS.implements
class BitFlip(S.BitFlip, FaultKind):

    def __init__(self, *a):
        super().__init__(*a)
        n = self.count = int(self.settings["count"])
        # Flip instants are fixed up front from the fault's seed: same RunSpec, same flips. A
        # window a condition opens draws the same fractions of its length now, and places them
        # when it opens (`opened`).
        f, waits = self.fault, self.start == math.inf
        spread = not self.instant and (f.end_s is None or f.end_s > f.start_s if waits
                                       else min(self.end, self.duration_s) > self.start)
        self._fractions = self.rng.random(n) if spread else None
        self._picks = None  # a node target: the site index of each flip
        self._sites: list[str] = []
        self.times = np.zeros(0) if waits else self._place()
        self._queues: dict[str, list[float]] = {self.fault.target: list(self.times)}
        self._next = 0  # tensor sites: flips consumed so far
        self._tensor = None
        self.clock = lambda: 0.0

    def _place(self):
        """The flip instants [s] in the window (all at its start for an instant or an empty one)."""
        end = min(self.end, self.duration_s)
        if self._fractions is None or end <= self.start:
            return np.full(self.count, float(self.start))
        return np.sort(self.start + (end - self.start) * self._fractions)

    def _queue_flips(self) -> None:
        if self._picks is None:
            if self._tensor is None:
                self._queues = {self.fault.target: list(self.times)}
            return
        self._queues = {s: [float(t) for t, p in zip(self.times, self._picks) if p == i]
                        for i, s in enumerate(self._sites)}

    def opened(self) -> None:
        self.times = self._place()
        self._queue_flips()
        if self._tensor is not None:
            self._tensor.arm_next()

    def bind(self, binding: Binding) -> None:
        self.clock = binding.clock
        target = self.fault.target
        if target in binding.nodes:
            # A node target: each flip lands on one of the node's sites, drawn up front.
            self._sites = sorted(binding.nodes[target])
            self._picks = self.rng.integers(len(self._sites), size=self.count)
            self._queue_flips()
        elif target in binding.tensor_sites and target not in binding.sites():
            from addt_dsl.runtime.faults.tensor import TensorFlipper

            self._queues = {}
            self._tensor = TensorFlipper(self, target, binding.tensor_sites[target], str(self.settings["tensor"]),
                                         binding.at)

    def close(self) -> None:
        if self._tensor is not None:
            self._tensor.close()

    # ---- bit choice
    def _bit_in(self, lo: int, hi: int, width: int) -> int:
        bit = int(self.settings["bit"])
        if bit >= 0:
            if bit >= width:
                raise ValueError(f"bit {bit} does not exist in a {width}-bit value")
            return bit
        return int(self.rng.integers(lo, hi))

    def bit_for(self, dtype) -> int:
        """A bit for a tensor element of `dtype` (index, or drawn from the IEEE field)."""
        import torch

        from addt_dsl.runtime.faults.tensor import bit_range

        width = torch.finfo(dtype).bits
        return self._bit_in(*bit_range(dtype, str(self.settings["field"])), width)

    def pending(self) -> bool:
        """Tensor sites: whether flips remain to be taken."""
        return self._next < len(self.times)

    def next_time(self) -> float:
        """Tensor sites: the instant [s] of the next flip to be taken."""
        return float(self.times[self._next])

    def due(self) -> int:
        """Tensor sites: how many flips are due now (and mark them consumed)."""
        now = self.clock() + 1e-12
        n = 0
        while self._next < len(self.times) and self.times[self._next] <= now:
            self._next += 1
            n += 1
        return n

    # ---- stored state
    def on_state(self, site, state, time_s):
        """Flip the due bits of `state` (the node's (name, value) pairs) in place; a flip
        whose instant came while the state was empty waits for the next read that holds
        something, as a scalar-site flip waits for the next value through its site."""
        queue = self._queues.get(site)
        if not queue or queue[0] > time_s + 1e-12 or not state:
            return False
        while queue and queue[0] <= time_s + 1e-12:
            queue.pop(0)
            i = int(self.rng.integers(len(state)))  # the element, then the bit: one stream
            bit = self._bit_in(*BIT_FIELDS_F64[str(self.settings["field"])], 64)
            name, before = state[i]
            state[i] = (name, flip_stored_bit(before, bit))
            self.record(time_s, f"{site}:{name}", state[i][1], bit=bit, before=before)
        return True

    # ---- scalar sites
    def on_value(self, site, value, time_s):
        queue = self._queues.get(site)
        if not queue or queue[0] > time_s + 1e-12:
            return value
        out = value
        while queue and queue[0] <= time_s + 1e-12:
            queue.pop(0)
            bit = self._bit_in(*BIT_FIELDS_F64[str(self.settings["field"])], 64)
            before = out
            out = flip_float64_bit(out, bit)
            self.record(time_s, site, out, bit=bit, before=before)
        return out


@FAULTS.implements
class StuckAt(S.StuckAt, FaultKind):

    def __init__(self, *a):
        super().__init__(*a)
        self._holding: set[str] = set()  # sites currently overriding a different true value

    def on_value(self, site, value, time_s):
        if not self.active(time_s):
            return value
        stuck = float(self.settings["value"])
        if value == stuck:
            self._holding.discard(site)
        elif site not in self._holding:
            self._holding.add(site)
            self.record(time_s, site, stuck, before=value)
        return stuck


@FAULTS.implements
class RandomValue(S.RandomValue, FaultKind):
    _BATCH = 256

    def __init__(self, *a):
        super().__init__(*a)
        self._values: list[float] = []

    def on_value(self, site, value, time_s):
        if not self.active(time_s):
            return value
        if not self._values:
            # Drawn in batches (the same stream as one draw at a time), consumed in order.
            batch = self.rng.uniform(float(self.settings["low"]), float(self.settings["high"]), self._BATCH)
            self._values = batch.tolist()[::-1]
        out = self._values.pop()
        self.record_series(time_s, site, out, value)
        return out
