"""Roads the stack's unit tests share: inline roads sampled as the loop samples them."""

from __future__ import annotations

import math

from addt_dsl.plan import RoadPlan, SegmentPlan
from addt_dsl.road.roadspec import build_network
from addt_dsl.runtime.fastroad import FastRoad


def road(*segments) -> FastRoad:
    """A one-road network of `segments` with two right lanes, as a `FastRoad`."""
    plan = RoadPlan(name="r", source="inline", segments=list(segments), right_lanes=2)
    network = build_network([plan])["r"]
    return FastRoad(network.road(next(iter(network.roads))))


STRAIGHT = road(SegmentPlan(kind="line", length_m=500.0))
# A U turn: the two straights run 100 m apart, so a point between them has two near samples.
HAIRPIN = road(SegmentPlan(kind="line", length_m=200.0),
               SegmentPlan(kind="arc", length_m=50.0 * math.pi, curvature_per_m=0.02),
               SegmentPlan(kind="line", length_m=200.0))
