"""Timing faults: latency spikes and a slowed node."""

from __future__ import annotations

from addt_dsl.registry import FAULTS
from addt_dsl.specs import faults as S
from addt_dsl.runtime.faults.base import FaultKind


@FAULTS.implements
class Spike(S.Spike, FaultKind):

    def extra_latency(self, node, time_s, base_s):
        if not self.active(time_s):
            return 0.0
        self.record(time_s, node, float(self.settings["by"]))
        return float(self.settings["by"])


@FAULTS.implements
class Slow(S.Slow, FaultKind):

    def extra_latency(self, node, time_s, base_s):
        if not self.active(time_s):
            return 0.0
        extra = (float(self.settings["factor"]) - 1.0) * base_s
        self.record(time_s, node, extra, factor=float(self.settings["factor"]))
        return extra
