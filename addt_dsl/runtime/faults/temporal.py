"""Sensor temporal faults: frames lost, late, or stamped with the wrong time."""

from __future__ import annotations

from addt_dsl.registry import FAULTS
from addt_dsl.specs import faults as S
from addt_dsl.runtime.faults.base import FaultKind


@FAULTS.implements
class Drop(S.Drop, FaultKind):

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


@FAULTS.implements
class Delay(S.Delay, FaultKind):

    def on_frame(self, frame, time_s):
        if not self.active(time_s):
            return frame, 0.0
        jitter = float(self.settings["jitter"])
        delay = float(self.settings["by"]) + (jitter * self.rng.random() if jitter > 0 else 0.0)
        self.record(time_s, frame.sensor, delay)
        return frame, delay


@FAULTS.implements
class Skew(S.Skew, FaultKind):

    def on_frame(self, frame, time_s):
        if self.active(time_s):
            frame.stamp_s += float(self.settings["by"])
            self.record(time_s, frame.sensor, frame.stamp_s, offset_s=float(self.settings["by"]))
        return frame, 0.0
