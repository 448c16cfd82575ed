"""Timing faults: latency spikes and a slowed node."""

from __future__ import annotations

from addt_dsl import units
from addt_dsl.registry import FAULTS, ParamSpec
from addt_dsl.runtime.faults.base import FaultKind


@FAULTS.register
class Spike(FaultKind):
    keyword = "spike"
    target_kind = "node"
    params = (ParamSpec("by", units.TIME, required=True, low=0.0, high=10.0, doc="added latency"),)
    doc = ("A node's outputs are published later by a fixed amount during the window (e.g. a "
           "preempted process). Recorded per publication: `value` is the added latency [s].")

    def extra_latency(self, node, time_s, base_s):
        if not self.active(time_s):
            return 0.0
        self.record(time_s, node, float(self.settings["by"]))
        return float(self.settings["by"])


@FAULTS.register
class Slow(FaultKind):
    keyword = "slow"
    target_kind = "node"
    params = (ParamSpec("factor", None, kind="number", default=2.0, low=1.0, high=1000.0,
                        doc="latency scale factor"),)
    doc = ("A node runs slower (thermal throttling, a contended core): its latency is multiplied "
           "by `factor` during the window. Recorded per publication: `value` is the added latency [s].")

    def extra_latency(self, node, time_s, base_s):
        if not self.active(time_s):
            return 0.0
        extra = (float(self.settings["factor"]) - 1.0) * base_s
        self.record(time_s, node, extra, factor=float(self.settings["factor"]))
        return extra
