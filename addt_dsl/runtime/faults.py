"""Fault kinds, one registered class per DSL keyword, and the schedule that applies them.

Each fault has a target (a sensor, or a stack fault site such as `control.steer`), a time
window, settings and its own seed. Hooks are called by the loop at fixed points:
`before_capture` (sensor pose), `on_frame` (drop/delay/skew), `on_value` (a node's
variable or output), `extra_latency` (timing). Every injection is recorded as an event
with its location and injected value.
"""

from __future__ import annotations

import math
import struct

import numpy as np

from addt_dsl import units
from addt_dsl.registry import FAULTS, ParamSpec


class FaultKind:
    keyword = ""
    target_kind = "sensor"  # "sensor" | "site" (a stack node's variable/output/tensor) | "node"
    params: tuple[ParamSpec, ...] = ()
    doc = ""

    def __init__(self, fault, step_s: float, duration_s: float, record):
        self.fault = fault
        self.settings = {p.name: fault.settings.get(p.name, p.default) for p in self.params}
        self.start = fault.start_s
        self.end = fault.end_s if fault.end_s is not None else math.inf
        self.instant = fault.end_s is not None and fault.end_s == fault.start_s
        if self.instant:
            self.end = fault.start_s + step_s * 0.999
        self.rng = np.random.default_rng(fault.seed)
        self.record = record  # callable(time_s, detail dict)
        self.duration_s = duration_s

    def active(self, time_s: float) -> bool:
        return self.start <= time_s <= self.end

    # Hooks; a kind overrides the ones it needs.
    def before_capture(self, sensor, time_s: float) -> None:
        pass

    def on_frame(self, frame, time_s: float):
        """Return (frame or None if dropped, extra delivery delay [s])."""
        return frame, 0.0

    def on_value(self, site: str, value: float, time_s: float) -> float:
        return value

    def extra_latency(self, node: str, time_s: float, base_s: float) -> float:
        return 0.0


# ---------------------------------------------------------------- sensor, temporal

@FAULTS.register
class Drop(FaultKind):
    keyword = "drop"
    params = (
        ParamSpec("rate", units.DIMENSIONLESS, default=1.0, low=0.0, high=1.0,
                  doc="probability that a frame is dropped (Bernoulli), e.g. `5 %`"),
        ParamSpec("burst", None, kind="int", default=1, low=1, high=1000,
                  doc="frames lost per drop event"),
    )
    doc = "Sensor frames are lost."

    def __init__(self, *a):
        super().__init__(*a)
        self._pending = 0

    def on_frame(self, frame, time_s):
        if not self.active(time_s):
            return frame, 0.0
        if self._pending > 0:
            self._pending -= 1
            self.record(time_s, {"sensor": frame.sensor, "dropped": True, "burst": True})
            return None, 0.0
        if self.rng.random() < float(self.settings["rate"]):
            self._pending = int(self.settings["burst"]) - 1
            self.record(time_s, {"sensor": frame.sensor, "dropped": True})
            return None, 0.0
        return frame, 0.0


@FAULTS.register
class Delay(FaultKind):
    keyword = "delay"
    params = (
        ParamSpec("by", units.TIME, required=True, low=0.0, high=10.0, doc="added transport delay"),
        ParamSpec("jitter", units.TIME, default=0.0, low=0.0, high=10.0, doc="uniform extra delay in [0, jitter]"),
    )
    doc = ("Frames arrive late. Frames older than the stack's stale-input threshold on arrival "
           "are discarded by the stack: an effective drop, as in the paper.")

    def on_frame(self, frame, time_s):
        if not self.active(time_s):
            return frame, 0.0
        delay = float(self.settings["by"]) + float(self.settings["jitter"]) * self.rng.random()
        self.record(time_s, {"sensor": frame.sensor, "delay_s": delay})
        return frame, delay


@FAULTS.register
class Skew(FaultKind):
    keyword = "skew"
    params = (ParamSpec("by", units.TIME, required=True, low=-10.0, high=10.0, doc="timestamp offset"),)
    doc = "Frame timestamps are wrong by a fixed offset (the data is on time)."

    def on_frame(self, frame, time_s):
        if self.active(time_s):
            frame.stamp_s += float(self.settings["by"])
        return frame, 0.0


# ---------------------------------------------------------------- sensor, spatial

_AXES = ("x", "y", "z", "roll", "pitch", "yaw")


@FAULTS.register
class Shift(FaultKind):
    keyword = "shift"
    params = tuple(ParamSpec(a, units.LENGTH if a in "xyz" else units.ANGLE, default=0.0,
                             low=-10.0 if a in "xyz" else -math.pi, high=10.0 if a in "xyz" else math.pi,
                             doc=f"{a} offset of the actual mount from the calibrated one")
                   for a in _AXES) + (
        ParamSpec("ramp", units.TIME, default=0.0, low=0.0, doc="drift: reach the full shift over this time"),)
    doc = "The sensor's mount moves (sudden shift, or gradual drift with `ramp`); calibration does not."

    def before_capture(self, sensor, time_s):
        if time_s < self.start:
            return
        ramp = float(self.settings["ramp"])
        k = 1.0 if ramp <= 0 else min(1.0, (time_s - self.start) / ramp)
        sensor.actual = sensor.nominal.shifted(**{a: k * float(self.settings[a]) for a in _AXES})


# ---------------------------------------------------------------- compute

def flip_float64_bit(value: float, bit: int) -> float:
    (bits,) = struct.unpack("<Q", struct.pack("<d", value))
    (out,) = struct.unpack("<d", struct.pack("<Q", bits ^ (1 << bit)))
    return out


BIT_FIELDS_F64 = {"sign": (63, 64), "exponent": (52, 63), "mantissa": (0, 52), "any": (0, 64)}


@FAULTS.register
class BitFlip(FaultKind):
    keyword = "bitflip"
    target_kind = "site"
    params = (
        ParamSpec("count", None, kind="int", default=1, low=1, high=10000, doc="number of flips in the window"),
        ParamSpec("bit", None, kind="int", default=-1, low=-1, high=63, doc="bit index (-1: chosen by `field`)"),
        ParamSpec("field", None, kind="word", default="any", choices=tuple(BIT_FIELDS_F64),
                  doc="IEEE-754 field the random bit is drawn from"),
        ParamSpec("tensor", None, kind="word", default="weights", choices=("weights", "activations"),
                  doc="for tensor sites: weights (persistent) or activations (one inference)"),
    )
    doc = "Flip bits in a stack variable, output or tensor (transient, one use per flip)."

    def __init__(self, *a):
        super().__init__(*a)
        end = min(self.end, self.duration_s)
        n = int(self.settings["count"])
        # Flip instants are fixed up front from the fault's seed: same RunSpec, same flips.
        self.times = np.sort(self.start + (end - self.start) * self.rng.random(n)) if end > self.start \
            else np.full(n, self.start)
        self._next = 0

    def _bit(self) -> int:
        if int(self.settings["bit"]) >= 0:
            return int(self.settings["bit"])
        lo, hi = BIT_FIELDS_F64[str(self.settings["field"])]
        return int(self.rng.integers(lo, hi))

    def on_value(self, site, value, time_s):
        out = value
        while self._next < len(self.times) and self.times[self._next] <= time_s:
            bit = self._bit()
            out = flip_float64_bit(out, bit)
            self.record(time_s, {"site": site, "bit": bit, "before": value, "after": out})
            self._next += 1
        return out


@FAULTS.register
class StuckAt(FaultKind):
    keyword = "stuck"
    target_kind = "site"
    params = (ParamSpec("value", None, kind="number", default=0.0, doc="value the site is stuck at (SI)"),)
    doc = "A variable or output is stuck at a value during the window."

    def on_value(self, site, value, time_s):
        if not self.active(time_s):
            return value
        stuck = float(self.settings["value"])
        if value != stuck:
            self.record(time_s, {"site": site, "before": value, "after": stuck})
        return stuck


@FAULTS.register
class RandomValue(FaultKind):
    keyword = "random_value"
    target_kind = "site"
    params = (ParamSpec("low", None, kind="number", default=-1.0, doc="lower bound (SI)"),
              ParamSpec("high", None, kind="number", default=1.0, doc="upper bound (SI)"))
    doc = "A variable or output takes uniform random values during the window."

    def on_value(self, site, value, time_s):
        if not self.active(time_s):
            return value
        out = float(self.rng.uniform(float(self.settings["low"]), float(self.settings["high"])))
        self.record(time_s, {"site": site, "before": value, "after": out})
        return out


# ---------------------------------------------------------------- timing

@FAULTS.register
class Spike(FaultKind):
    keyword = "spike"
    target_kind = "node"
    params = (ParamSpec("by", units.TIME, required=True, low=0.0, high=10.0, doc="added latency"),)
    doc = "A node's outputs are published later by a fixed amount during the window."

    def extra_latency(self, node, time_s, base_s):
        if not self.active(time_s):
            return 0.0
        self.record(time_s, {"node": node, "extra_s": float(self.settings["by"])})
        return float(self.settings["by"])


@FAULTS.register
class Slow(FaultKind):
    keyword = "slow"
    target_kind = "node"
    params = (ParamSpec("factor", None, kind="number", default=2.0, low=1.0, high=1000.0,
                        doc="latency scale factor"),)
    doc = "A node runs slower: its latency is multiplied by `factor` during the window."

    def extra_latency(self, node, time_s, base_s):
        return (float(self.settings["factor"]) - 1.0) * base_s if self.active(time_s) else 0.0


class FaultSchedule:
    """The concrete faults of one run, indexed by target for the loop's hooks."""

    def __init__(self, faults, step_s: float, duration_s: float, events: list):
        from addt_dsl.runtime.trace import Event

        self.by_target: dict[str, list[FaultKind]] = {}
        self.events = events
        for f in faults:
            cls = FAULTS.get(f.kind)

            def record(time_s, detail, _f=f):
                events.append(Event(time_s, "fault", {"index": _f.index, "kind": _f.kind,
                                                      "target": _f.target, **detail}))

            self.by_target.setdefault(f.target, []).append(cls(f, step_s, duration_s, record))

    def for_target(self, target: str) -> list[FaultKind]:
        return self.by_target.get(target, [])

    def targets(self) -> set[str]:
        return set(self.by_target)
