"""The agents' state as arrays with a leading runs axis (`AgentArrays`), and the view of one
agent in them (`AgentState`).

The numbers the loop moves every step (station, offset, speed, acceleration, ground scale)
live in one float block [field, run, agent] per batch, each run's agents padded to the
batch's largest count (`valid` says which slots hold an agent); the agents' phases
(`agents.Fleets`) read and write the block with one index per field over every live run.
Whether an agent was teleported this step (`placed`) is a [run, agent] mask beside it.

`AgentState` is how code that must read or move one agent sees it (behaviours, scripts,
triggers, the per-agent step, oracles): its numeric fields are properties over its slot in
the block, not copies, so nothing is synchronised between the two; its other fields (lane,
the lateral manoeuvre, the lane anchor) are its own. An agent starts in a block of its own;
a run's set-up moves its agents into a block of one run (`agents.Fleet`), and the batch's
loop moves every run's agents into the batch's block (`AgentArrays.adopt`): the values move
with them, bit for bit.
"""

from __future__ import annotations

import numpy as np

# The block's fields, in this order (the agents' phases read S..ACCEL as one slice).
FIELDS = ("s", "t", "speed", "accel", "ground_scale")
S, T, SPEED, ACCEL, SCALE = range(len(FIELDS))


class AgentArrays:
    """Every agent of some runs, one slot each: `values[field, run, i]` (fields `FIELDS`; [m],
    [m], [m/s], [m/s^2], [m/m]), run r's agents in slots 0..sizes[r]-1 in declaration order,
    the rest padding (`valid` False; ground scale 1, the rest 0, never read); `placed[run, i]`:
    teleported this step; `anchored[run]`: how many of the run's agents hold a lane anchor
    (they are stepped one by one). `flat` is `values` as [field, run * width + i], the index
    the phases use (`rows`); `cells` is `flat` as a memoryview, read and written one value at
    a time by the agents' views (a Python float in ~40 ns, numpy's `item` takes ~90 ns)."""

    def __init__(self, sizes: list[int]):
        self.sizes = list(sizes)
        runs, width = len(self.sizes), max(self.sizes, default=0)
        self.width = width
        self.values = np.zeros((len(FIELDS), runs, width))
        self.values[SCALE] = 1.0
        self.flat = self.values.reshape(len(FIELDS), runs * width)
        self.stride = runs * width  # between one field's value of a slot and the next field's
        self.cells = memoryview(self.values.reshape(-1))
        self.valid = np.arange(width) < np.array(self.sizes, dtype=np.intp).reshape(-1, 1)
        self.placed = np.zeros((runs, width), dtype=bool)
        self.placed_cells = memoryview(self.placed.reshape(-1))
        self.anchored = [0] * runs

    def rows(self, run: int) -> np.ndarray:
        """The `flat` indices of run `run`'s agents, in declaration order."""
        return np.arange(self.sizes[run], dtype=np.intp) + run * self.width

    @classmethod
    def adopt(cls, groups: list[list[AgentState]]) -> AgentArrays:
        """A block for these runs' agents (run r's are `groups[r]`): each agent's values move
        into its slot and the agent becomes a view of it."""
        block = cls([len(g) for g in groups])
        for r, agents in enumerate(groups):
            for i, a in enumerate(agents):
                a._move_to(block, r, r * block.width + i)
        return block


def _value(field: int, doc: str) -> property:
    def get(self) -> float:
        return self._cells[self._k + field * self._stride]

    def put(self, value: float) -> None:
        self._cells[self._k + field * self._stride] = value

    return property(get, put, doc=doc)


class AgentState:
    """Road-frame state of a traffic agent (m, m/s): a view of its slot in an `AgentArrays`
    block for the numbers the loop moves, its own attributes for the rest."""

    s = _value(S, "station along its road or path [m]")
    t = _value(T, "lateral offset from the reference line [m]")
    speed = _value(SPEED, "speed along its own path [m/s]")
    accel = _value(ACCEL, "acceleration of the last step [m/s^2]")
    # Ground covered per metre of station at its offset [m/m] (`FastRoad.ground_scale`),
    # set where it is posed: its station advances by speed / ground_scale.
    ground_scale = _value(SCALE, "ground covered per metre of station [m/m]")

    def __init__(self, name: str, road: str, s: float, t: float, speed: float, accel: float,
                 length_m: float, width_m: float, lane: int, t_target: float, t_start: float = 0.0,
                 lc_start_s: float = 0.0, lc_duration_s: float = 0.0, heading_rel: float = 0.0,
                 lc_shape: str = "quintic", lc_keeps_station: bool = False, moved: bool = False,
                 ground_scale: float = 1.0, lane_anchor: tuple | None = None, lc_centre: tuple | None = None,
                 placed: bool = False):
        self.name, self.road = name, road
        self.length_m, self.width_m = length_m, width_m
        self.lane, self.t_target, self.t_start = lane, t_target, t_start
        self.lc_start_s = lc_start_s  # time the current lateral manoeuvre began [s]
        self.lc_duration_s = lc_duration_s
        # Direction of motion relative to the road's +s direction [rad]; non-zero for
        # walkers: they move at this angle instead of following a lane.
        self.heading_rel = heading_rel
        self.lc_shape = lc_shape  # blend of the current lateral manoeuvre (see SHAPES)
        # The current lateral manoeuvre leaves the station's progress whole (a lane offset, as
        # esmini moves one); a lane change takes its sideways part from the step along the road.
        self.lc_keeps_station = lc_keeps_station
        self.moved = moved  # it has had a speed above 0: its declared yaw no longer holds
        # A lane change onto a lane whose centre moves along s (a lane that widens, a lane
        # offset): (stations, the target lane's centre there, its centre at the start); None
        # where the centre stays put (the change ends at `t_target`).
        self.lc_centre = lc_centre
        self._bind(AgentArrays([1]), 0, 0)  # a block of its own until a run adopts it
        self._lane_anchor = None
        self.s, self.t, self.speed, self.accel, self.ground_scale = s, t, speed, accel, ground_scale
        self.placed = placed
        self.lane_anchor = lane_anchor

    def _move_to(self, block: AgentArrays, run: int, k: int) -> None:
        """Carry this agent's values into slot `k` (of run `run`) of `block`; read and write there."""
        anchor, placed = self._lane_anchor, self.placed
        block.flat[:, k] = self._block.flat[:, self._k]
        self.lane_anchor = None  # (the old block's count)
        self._bind(block, run, k)
        self.placed, self.lane_anchor = placed, anchor

    def _bind(self, block: AgentArrays, run: int, k: int) -> None:
        self._block, self._run, self._k = block, run, k
        self._cells, self._stride, self._placed = block.cells, block.stride, block.placed_cells

    # Teleported in this step: it does not move along its road until the next one (esmini
    # moves no entity whose position an action set in the step).
    @property
    def placed(self) -> bool:
        return self._placed[self._k]

    @placed.setter
    def placed(self, value: bool) -> None:
        self._placed[self._k] = value

    # After a lane change: (lane, road of the path's leg or None until the next step, that
    # lane's centre t [m] last step). While it holds, a move of the lane's centre in the road's
    # frame (a lane narrowing beside it, a route's reference crossing over where its own lane
    # ends) moves the agent with it, as esmini keeps an entity's lane and offset
    # (`RunState.follow_lane`); None: it keeps its offset t.
    @property
    def lane_anchor(self) -> tuple | None:
        return self._lane_anchor

    @lane_anchor.setter
    def lane_anchor(self, value: tuple | None) -> None:
        change = (value is not None) - (self._lane_anchor is not None)
        if change:
            self._block.anchored[self._run] += change
        self._lane_anchor = value

    def __repr__(self) -> str:
        return (f"AgentState({self.name!r}, road={self.road!r}, s={self.s!r}, t={self.t!r}, "
                f"speed={self.speed!r}, accel={self.accel!r})")
