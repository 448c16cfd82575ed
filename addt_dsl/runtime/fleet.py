"""Car-following agents stepped as arrays: the leader lookup and the IDM step of every
agent at once (numpy over agents), with the floats of the per-agent code.

The loop steps agents one after another in declaration order, so agent i reads the
agents before it where they have already moved this step (their new station, offset
and speed) and those after it where they were. `Views.leaders` answers that lookup for
every agent at once from a *view*, a table of members sorted by station: the Jacobi view
(everyone where they were, and the ego) or the sequential one (earlier agents moved).
Its answer for agent i is `neighbours.leader_scan` over the members as agent i sees
them: the nearest member ahead on its road within the lane window, the first in member
order on equal gaps (agents in declaration order, then the ego).

The agents phase (`agents.Fleet.step`) solves the sequential step as a fixed point: it
steps every agent against the Jacobi view, then asks the sequential view with the earlier
agents moved; when no acceleration changes, the new states are those of the sequential
loop (agent i's answer depends only on agents before it, so the fixed point is unique).
Agents declared behind their leaders settle at the first check; a chain declared front
to back needs a round per car and is left to the per-agent loop after `MAX_ROUNDS`.

Bit for bit: +, -, *, /, sqrt and comparisons in numpy round as Python's floats do, in
the same order of operations; powers stay Python's (`pow`, libm), as numpy's may not.
"""

from __future__ import annotations

from itertools import repeat

import numpy as np

from addt_dsl.runtime import behaviors
from addt_dsl.runtime.behaviors import IdmParams
from addt_dsl.runtime.neighbours import LANE_WINDOW_M, STOP_SLACK_M, bumper_gap, outside_lane

WINDOW = 12  # view entries examined per agent at first (widened where not enough) [-]
MAX_ROUNDS = 3  # fixed-point checks before a step is left to the scalar loop


class Views:
    """The members as the agents see them, as one table per view sorted by station: a column
    per entry with rows (station, offset, speed, length, member index, and the keys lo..hi
    of the agents that see it, key = road code * (n + 1) + agent index: an entry is seen
    only on its road), and a last column past every station that nobody sees.

    The Jacobi view has each agent's old state (seen by all: an agent's own entry is never
    strictly ahead of it) and the ego. The sequential view has the old states seen by the
    agents before them, the new states seen by the agents after them, and the ego."""

    def __init__(self, length: np.ndarray, road: np.ndarray, ego_length: float, ego_road: int):
        n = self.n = len(length)
        self.longest = max(float(length.max()), ego_length)
        m = np.arange(n, dtype=float)
        base = road * (n + 1.0)
        self.key = base + m  # each agent's own key
        ego_base = ego_road * (n + 1.0)
        ego = (ego_length, n, ego_base, ego_base + n - 1)
        self._jacobi = np.zeros((7, n + 2))
        self._jacobi[3:, :n] = (length, m, base, base + n - 1)
        self._jacobi[3:, n] = ego
        self._seq = np.zeros((7, 2 * n + 2))
        self._seq[3:, :n] = (length, m, base, base + m - 1.0)
        self._seq[3:, n:2 * n] = (length, m, base + m + 1.0, base + n - 1)
        self._seq[3:, 2 * n] = ego
        for table in (self._jacobi, self._seq):
            table[:, -1] = (np.inf, 0.0, 0.0, 0.0, -1.0, 0.0, -1.0)

    def jacobi(self, s, t, v, ego) -> np.ndarray:
        """Everyone where they were (`ego`: station, offset, speed)."""
        table = self._jacobi.copy()
        n = self.n
        table[:3, :n] = (s, t, v)
        table[:3, n] = ego
        return table[:, np.argsort(table[0], kind="stable")]

    def sequential(self, s, t, v, new, ego) -> np.ndarray:
        """Earlier agents at their `new` (station, offset, speed), later ones where they were."""
        table = self._seq.copy()
        n = self.n
        table[:3, :n] = (s, t, v)
        table[:3, n:2 * n] = new
        table[:3, 2 * n] = ego
        return table[:, np.argsort(table[0], kind="stable")]

    def leaders(self, table, s, t, length, window_m: float = LANE_WINDOW_M):
        """(found, gap [m], leader speed [m/s]) per agent from a view's sorted table."""
        first = np.searchsorted(table[0], s, side="right")  # the first entry strictly ahead
        found, best, speed, done = self._window(table, first, WINDOW, s, t, length, self.key, window_m)
        if done.all():
            return found, best, speed
        rows, width = np.flatnonzero(~done), 4 * WINDOW
        while len(rows):  # not settled within the window: a wider one
            f, b, v, done = self._window(table, first[rows], width, s[rows], t[rows], length[rows],
                                         self.key[rows], window_m)
            found[rows], best[rows], speed[rows] = f, b, v
            rows, width = rows[~done], 4 * width
        return found, best, speed

    def _window(self, table, first, width, s, t, length, key, window_m):
        """`leaders` from the `width` entries ahead of each agent; `done` where no entry
        beyond can be nearer (none left, or `neighbours.LeaderIndex`'s bound)."""
        last = table.shape[1] - 1
        cols = np.minimum(first[:, None] + np.arange(width), last)
        es, et, ev, el, em, lo, hi = table[:, cols]
        k = key[:, None]
        mask = (lo <= k) & (k <= hi) & ~outside_lane(et, t[:, None], window_m)
        g = np.where(mask, bumper_gap(es, el, s[:, None], length[:, None]), np.inf)
        best = g.min(axis=1)
        tied = mask & (g == best[:, None])  # equal gaps: the least member index
        col = np.where(tied, em, np.inf).argmin(axis=1)
        speed = ev[np.arange(len(s)), col]
        next_s = table[0, np.minimum(first + width, last)]
        done = (next_s == np.inf) | (next_s - s - 0.5 * (self.longest + length) > best + STOP_SLACK_M)
        return best < np.inf, best, speed, done


class ARRAYS:
    """`behaviors.Idm`'s float operations on numpy arrays, with the same values: `max(0.0, x)`
    and `max(x, low)` as the first argument where the second is not larger, powers by libm."""

    @staticmethod
    def power(x, n: int) -> np.ndarray:
        k = len(x)
        return np.fromiter(map(pow, x.tolist(), repeat(n, k)), float, k)

    @staticmethod
    def positive(x):
        return np.where(x > 0.0, x, 0.0)

    @staticmethod
    def at_least(x, low):
        return np.where(low > x, low, x)


def idm_params(settings: list[dict]) -> IdmParams:
    """Per-agent IDM settings as arrays (`behaviors.IdmParams.of` of each)."""
    ps = [IdmParams.of(p) for p in settings]
    return IdmParams(*(np.array([float(getattr(p, k)) for p in ps]) for k in
                       ("v0", "accel", "time_gap", "min_gap", "two_sqrt_ab")))


def idm_free(p: IdmParams, v) -> np.ndarray:
    """`behaviors.idm_free` of every agent."""
    return behaviors.idm_free(p, v, ARRAYS)


def idm_accel(p: IdmParams, v, free, found, gap, lead_speed) -> np.ndarray:
    """`behaviors.Idm.accel` of every agent [m/s^2] (`free`: `idm_free`; no leader where not `found`)."""
    g = np.where(found, gap, 1.0)
    return np.where(found, behaviors.idm_accel(p, v, free, g, lead_speed, ARRAYS), p.accel * free)
