"""Lane sections and lane borders.

Conventions (OpenDRIVE): lane ids < 0 lie to the right of the reference line (looking
along +s), ids > 0 to the left, lane 0 is the zero-width centre lane. ``t`` [m] is the
lateral offset from the reference line, positive to the left. The centre lane sits at
``t = laneOffset(s)``; lane k's inner border is lane (k -/+ 1)'s outer border.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from .geometry import CubicProfile

DRIVING_TYPES = frozenset({"driving"})


@dataclass(frozen=True)
class Lane:
    """One lane of a lane section; ``width`` is a function of ds = s - section start [m]."""

    id: int
    type: str
    width: CubicProfile
    level: bool = False
    predecessors: tuple[int, ...] = ()
    successors: tuple[int, ...] = ()

    @property
    def side(self) -> int:
        """+1 left of the reference line, -1 right, 0 centre."""
        return (self.id > 0) - (self.id < 0)


@dataclass(frozen=True)
class LaneSection:
    """Lanes valid on ``[s0, s1)`` [m] (the last section includes s1 = road length).

    ``left`` is ordered 1, 2, ...; ``right`` is ordered -1, -2, ... (inside out).
    """

    s0: float
    s1: float
    left: tuple[Lane, ...] = ()
    right: tuple[Lane, ...] = ()
    center_type: str = "none"
    _by_id: dict = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        for side, lanes in ((1, self.left), (-1, self.right)):
            expected = [side * (i + 1) for i in range(len(lanes))]
            if [lane.id for lane in lanes] != expected:
                raise ValueError(
                    f"lane ids on the {'left' if side > 0 else 'right'} side must be "
                    f"{expected} (inside out), got {[lane.id for lane in lanes]}"
                )
        object.__setattr__(self, "_by_id", {lane.id: lane for lane in self.left + self.right})

    @property
    def lane_ids(self) -> tuple[int, ...]:
        """All non-centre lane ids of the section, left to right (n..1, -1..-m)."""
        return tuple(lane.id for lane in reversed(self.left)) + tuple(lane.id for lane in self.right)

    def lane(self, lane_id: int) -> Optional[Lane]:
        return self._by_id.get(lane_id)

    def side_borders(self, side: int, ds: np.ndarray, offset: np.ndarray) -> np.ndarray:
        """Border t [m] of one side, shape (n_lanes + 1, *ds.shape).

        Row 0 is the centre lane (= ``offset``), row k the outer border of lane side*k.
        """
        lanes = self.left if side > 0 else self.right
        rows = [np.asarray(offset, dtype=float)]
        for lane in lanes:
            rows.append(rows[-1] + side * np.asarray(lane.width(ds)))
        return np.stack(rows)

    def side_border_rates(self, side: int, ds: np.ndarray, offset_rate: np.ndarray) -> np.ndarray:
        """d(border t)/ds [-], same layout as :meth:`side_borders`."""
        lanes = self.left if side > 0 else self.right
        rows = [np.asarray(offset_rate, dtype=float)]
        for lane in lanes:
            rows.append(rows[-1] + side * np.asarray(lane.width.derivative(ds)))
        return np.stack(rows)


def lanes_at_t_array(section: LaneSection, ds: np.ndarray, offset: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Id of the lane of `section` containing each lateral offset `t` [m]; 0 marks "outside
    all lanes" (lane 0 has no width). Intervals are half-open towards the outside so that a
    point on a shared border belongs to the inner lane; t == laneOffset belongs to lane 1
    (or -1 without left lanes). Zero-width lanes never contain a point."""
    out = np.zeros(np.shape(t), dtype=int)
    for side in (1, -1):
        lanes = section.left if side > 0 else section.right
        if not lanes:
            continue
        borders = section.side_borders(side, ds, offset)
        for k in range(len(borders) - 1, 0, -1):
            inner, outer = borders[k - 1], borders[k]
            if side > 0:
                inside = (t >= inner) & ((t < outer) | ((k == len(borders) - 1) & (t == outer))) & (outer > inner)
            else:
                inside = (t <= inner) & ((t > outer) | ((k == len(borders) - 1) & (t == outer))) & (outer < inner)
            out = np.where(inside & (out == 0), side * k, out)
    return out
