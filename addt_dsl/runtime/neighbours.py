"""Who is ahead of whom on a road: the leader lookup of car-following behaviours.

`nearest_ahead` is the definition (`leader_scan` its gap and speed): among the actors on the agent's road strictly ahead
of it (station `s` greater) whose lateral offset `t` is within `window_m` of its own,
the one with the smallest bumper-to-bumper gap; on equal gaps the first in member
order (agents in declaration order, then the ego). It visits every actor, so a step
of N car-followers costs O(N^2).

`LeaderIndex` gives the same answers from per-road lists of stations kept sorted: a
query bisects to the first actor ahead and walks forward only while a nearer gap is
still possible. The loop rebuilds it once per step and repositions an agent when it
moves within the step (agents advance one after another, and a later agent's leader
is read where an earlier one has already moved to); the gap and the tie rule are
computed exactly as `leader_scan` does, so the two agree bit for bit.
"""

from __future__ import annotations

import math
from bisect import bisect_left, bisect_right
from typing import NamedTuple

LANE_WINDOW_M = 1.8  # |t - t_agent| within this: the same lane [m] (the one lane window of the runtime)
# Slack of the walk's stopping bound [m]: the bound is a lower limit of later gaps, in
# floating point within far less than this of the gap itself.
STOP_SLACK_M = 1e-6


class Member(NamedTuple):
    """An actor as the lookup sees it: its road (or path), station and offset [m], speed [m/s]."""

    name: str
    road: str
    s: float
    t: float
    speed: float
    length_m: float


# The two formulas of the definition (the agents' step kernel, `fleet.step`, writes them
# out compiled: the same operations in the same order).
def bumper_gap(s_m, length_m, s_agent, length_agent):
    """Bumper-to-bumper gap [m] from an agent at `s_agent` to a member at `s_m` ahead."""
    return s_m - s_agent - 0.5 * (length_m + length_agent)


def outside_lane(t_m, t_agent, window_m: float = LANE_WINDOW_M):
    """Whether a member's offset `t_m` is outside the agent's lane window."""
    return abs(t_m - t_agent) > window_m


def nearest_ahead(members, agent, window_m: float = LANE_WINDOW_M):
    """(member, gap [m]) of the nearest member ahead of `agent` on its road and within
    `window_m` of its offset, or (None, None): every member visited (the definition).

    Members have `name`, `road`, `s`, `t`, `length_m` (and `speed`, which `leader_scan` reads)."""
    best = best_gap = None
    for m in members:
        if m.road != agent.road or m.name == agent.name or outside_lane(m.t, agent.t, window_m):
            continue
        gap = bumper_gap(m.s, m.length_m, agent.s, agent.length_m)
        if m.s > agent.s and (best is None or gap < best_gap):
            best, best_gap = m, gap
    return best, best_gap


def leader_scan(members, agent, window_m: float = LANE_WINDOW_M):
    """(gap [m], speed [m/s]) of `nearest_ahead`, or None: the leader car-following reads."""
    m, gap = nearest_ahead(members, agent, window_m)
    return None if m is None else (gap, m.speed)


class LeaderIndex:
    """`leader_scan` answers from per-road station lists kept sorted.

    `members` is fixed at construction (their order breaks ties); their `s` may change,
    and then `rebuild()` (all of them) or `moved(i)` (one) must be called before the
    next query. `t`, `speed` and `length_m` are read live at each query."""

    def __init__(self, members, window_m: float = LANE_WINDOW_M):
        self.members = list(members)
        self.window_m = window_m
        self.position = {m.name: i for i, m in enumerate(self.members)}
        self._road = [m.road for m in self.members]
        self._max_length: dict[str, float] = {}
        self._keys: dict[str, list[float]] = {}  # road -> stations, ascending
        self._ids: dict[str, list[int]] = {}  # road -> member index, parallel to _keys
        self._key_of: list[float] = [0.0] * len(self.members)
        self._exact = False  # a non-finite station: answer by scanning
        self.rebuild()

    def rebuild(self) -> None:
        """Sort every road's stations afresh."""
        keys: dict[str, list[float]] = {}
        ids: dict[str, list[int]] = {}
        lengths: dict[str, float] = {}
        s_of = [m.s for m in self.members]
        self._exact = not all(math.isfinite(s) for s in s_of)
        for i in sorted(range(len(s_of)), key=s_of.__getitem__):
            road = self._road[i]
            keys.setdefault(road, []).append(s_of[i])
            ids.setdefault(road, []).append(i)
            length = self.members[i].length_m
            if length > lengths.get(road, -math.inf):
                lengths[road] = length
        self._keys, self._ids, self._max_length, self._key_of = keys, ids, lengths, s_of

    def moved(self, i: int) -> None:
        """Member `i`'s station changed: move it to its new place in its road's list."""
        s = self.members[i].s
        if not math.isfinite(s):
            self._exact = True
        if self._exact:
            return
        road = self._road[i]
        keys, ids = self._keys[road], self._ids[road]
        old = self._key_of[i]
        j = bisect_left(keys, old)
        while ids[j] != i:  # equal stations: find this member among them
            j += 1
        del keys[j], ids[j]
        k = bisect_right(keys, s)
        keys.insert(k, s)
        ids.insert(k, i)
        self._key_of[i] = s

    def leader(self, agent):
        """`leader_scan(members, agent)`, found by bisecting the agent's road list."""
        if self._exact:
            return leader_scan(self.members, agent, self.window_m)
        road = agent.road
        keys = self._keys.get(road)
        if keys is None:
            return None
        ids, members = self._ids[road], self.members
        s_a, t_a, len_a = agent.s, agent.t, agent.length_m
        half_longest = 0.5 * (self._max_length[road] + len_a)
        window = self.window_m
        best_gap = best_speed = None
        best_i = -1
        for j in range(bisect_right(keys, s_a), len(keys)):
            s = keys[j]
            # Every later member is at least this far ahead (bumpers included).
            if best_gap is not None and s - s_a - half_longest > best_gap + STOP_SLACK_M:
                break
            i = ids[j]
            m = members[i]
            if m.name == agent.name or outside_lane(m.t, t_a, window):
                continue
            gap = bumper_gap(s, m.length_m, s_a, len_a)
            if best_gap is None or gap < best_gap or (gap == best_gap and i < best_i):
                best_gap, best_speed, best_i = gap, m.speed, i
        return None if best_gap is None else (best_gap, best_speed)

