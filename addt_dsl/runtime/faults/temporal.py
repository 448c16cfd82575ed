"""Sensor temporal faults: frames lost, late, or stamped with the wrong time."""

from __future__ import annotations

from addt_dsl import units
from addt_dsl.registry import FAULTS, ParamSpec
from addt_dsl.runtime.faults.base import FaultKind


@FAULTS.register
class Drop(FaultKind):
    keyword = "drop"
    params = (
        ParamSpec("rate", units.DIMENSIONLESS, default=1.0, low=0.0, high=1.0,
                  doc="probability that a frame starts a drop event (Bernoulli), e.g. `5 %`"),
        ParamSpec("burst", None, kind="int", default=1, low=1, high=1000,
                  doc="consecutive frames lost per drop event"),
    )
    doc = ("Sensor frames are lost: each frame starts a drop event with probability `rate`; an "
           "event loses `burst` consecutive frames. Recorded per lost frame: `value` is the "
           "frame's timestamp [s].")

    def __init__(self, *a):
        super().__init__(*a)
        self._pending = 0

    def on_frame(self, frame, time_s):
        if not self.active(time_s):
            return frame, 0.0
        if self._pending > 0:
            self._pending -= 1
            self.record(time_s, frame.sensor, frame.stamp_s, dropped=True, burst=True)
            return None, 0.0
        if self.rng.random() < float(self.settings["rate"]):
            self._pending = int(self.settings["burst"]) - 1
            self.record(time_s, frame.sensor, frame.stamp_s, dropped=True)
            return None, 0.0
        return frame, 0.0


@FAULTS.register
class Delay(FaultKind):
    keyword = "delay"
    params = (
        ParamSpec("by", units.TIME, required=True, low=0.0, high=10.0, doc="added transport delay"),
        ParamSpec("jitter", units.TIME, default=0.0, low=0.0, high=10.0, doc="uniform extra delay in [0, jitter]"),
    )
    doc = ("Frames arrive late by `by` plus a uniform jitter. A frame older than the stack's "
           "stale-input threshold (`stack bev stale`) on arrival is discarded by the stack: an "
           "effective drop, as in the paper. Recorded per frame: `value` is the delay [s].")

    def on_frame(self, frame, time_s):
        if not self.active(time_s):
            return frame, 0.0
        jitter = float(self.settings["jitter"])
        delay = float(self.settings["by"]) + (jitter * self.rng.random() if jitter > 0 else 0.0)
        self.record(time_s, frame.sensor, delay)
        return frame, delay


@FAULTS.register
class Skew(FaultKind):
    keyword = "skew"
    params = (ParamSpec("by", units.TIME, required=True, low=-10.0, high=10.0, doc="timestamp offset"),)
    doc = ("Frame timestamps are wrong by a fixed offset (the data itself is on time). A "
           "negative skew makes frames look old, so the stack may discard them as stale. "
           "Recorded per frame: `value` is the stamped time [s].")

    def on_frame(self, frame, time_s):
        if self.active(time_s):
            frame.stamp_s += float(self.settings["by"])
            self.record(time_s, frame.sensor, frame.stamp_s, offset_s=float(self.settings["by"]))
        return frame, 0.0
