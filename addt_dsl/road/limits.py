"""Bounds on road geometry, so that a hostile or broken map is refused, not sampled.

Every road is sampled when it is built (a coarse projection grid, `road.py`) and again per
run (`fastroad.py`, every 0.25 m), and clothoids are integrated with a rule whose size
grows with their total turn. These bounds keep each of those allocations small; they are
far above anything a drivable road needs. A map beyond one is refused with an error that
names the limit (docs/roads.md lists them). To raise one, change it here: they are
module constants because the compiler and every run must agree on them.
"""

from __future__ import annotations

import math

MAX_ROAD_LENGTH_M = 50_000.0  # one road; split a longer road into consecutive roads
MAX_COORDINATE_M = 1.0e7  # |x|, |y|, |s| of any record (10,000 km from the map origin)
MAX_ABS_ATTRIBUTE = 1.0e9  # any other number in a map (coefficients, ids)
MAX_GEOMETRY_TURN_RAD = 4.0 * math.pi  # total heading change of one planView geometry
MAX_ROAD_SAMPLES = 200_000  # coarse projection samples of one road (length / 4 m + turn / 0.1 rad)
MAX_LANE_WIDTH_M = 100.0  # |width| of one lane anywhere along its section
MAX_LANE_OFFSET_M = 1_000.0  # |laneOffset| anywhere along the road
MAX_ELEVATION_M = 10_000.0  # |elevation| anywhere along the road
MAX_SUPERELEVATION_RAD = math.pi / 2  # |superelevation| anywhere along the road


class RoadLimitError(ValueError):
    """A road beyond one of the bounds above; `geometry` is the index of the planView
    geometry concerned, when there is one."""

    def __init__(self, message: str, geometry: int | None = None):
        super().__init__(message)
        self.geometry = geometry


def beyond(name: str, value: float, limit: float, unit: str, remedy: str = "") -> str:
    """The message for a value beyond a named limit."""
    hint = f"; {remedy}" if remedy else ""
    return (f"{value:.6g} {unit} is beyond the limit {name} = {limit:.6g} {unit} "
            f"(addt_dsl/road/limits.py{hint})")
