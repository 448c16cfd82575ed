"""Car-following agents stepped as arrays: the leader lookup and the IDM step of every
agent of a batch's runs at once (numpy over runs x agents, concatenated run after run),
with the floats of the per-agent code.

The loop steps agents one after another in declaration order, so agent i reads the
agents before it where they have already moved this step (their new station, offset
and speed) and those after it where they were. `Views.leaders` answers that lookup for
every agent at once from a *view*, a table of members with a block per run sorted by
station (no run sees another's members): the Jacobi view
(everyone where they were, and the ego) or the sequential one (earlier agents moved).
Its answer for agent i is `neighbours.leader_scan` over the members as agent i sees
them: the nearest member ahead on its road within the lane window, the first in member
order on equal gaps (agents in declaration order, then the ego).

The agents phase (`agents.Fleets.step`) solves the sequential step as a fixed point: it
steps every agent against the Jacobi view, then asks the sequential view with the earlier
agents moved; when no acceleration changes, the new states are those of the sequential
loop (agent i's answer depends only on agents before it, so the fixed point is unique;
checked per run: runs do not see each other, so a run once settled stays settled).
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
    """The members as the agents of a batch of runs see them, as one table per view: a block
    of columns per run (its entries sorted by station), then a last column past every
    station that nobody sees. A column's rows: station, offset, speed, length, member index,
    and the keys lo..hi of the agents that see it (key = the run's base + road code * (n + 1)
    + agent index, the run's bases apart: an entry is seen only on its road, in its run).

    The Jacobi view has each agent's old state (seen by all: an agent's own entry is never
    strictly ahead of it) and the ego. The sequential view has the old states seen by the
    agents before them, the new states seen by the agents after them, and the ego.

    `runs`: per run (agents' lengths [m], their road codes, the ego's length [m], its road
    code); a single run is a batch of one."""

    def __init__(self, runs):
        jacobi, seq, keys, longest, run_of = [], [], [], [], []
        jac_end, seq_end = [], []
        base_key = 0.0
        j_cols = s_cols = 0
        for r, (length, road, ego_length, ego_road) in enumerate(runs):
            n = len(length)
            m = np.arange(n, dtype=float)
            base = base_key + road * (n + 1.0)
            keys.append(base + m)  # each agent's own key
            ego_base = base_key + ego_road * (n + 1.0)
            ego = (ego_length, n, ego_base, ego_base + n - 1)
            block = np.zeros((7, n + 1))
            block[3:, :n] = (length, m, base, base + n - 1)
            block[3:, n] = ego
            jacobi.append(block)
            block = np.zeros((7, 2 * n + 1))
            block[3:, :n] = (length, m, base, base + m - 1.0)
            block[3:, n:2 * n] = (length, m, base + m + 1.0, base + n - 1)
            block[3:, 2 * n] = ego
            seq.append(block)
            longest.append(np.full(n, max(float(length.max()), ego_length)))
            run_of.append(np.full(n, r))
            j_cols, s_cols = j_cols + n + 1, s_cols + 2 * n + 1
            jac_end.append(np.full(n, j_cols))
            seq_end.append(np.full(n, s_cols))
            base_key += (max(int(road.max()), ego_road) + 1) * (n + 1.0)
        self.runs = len(runs)
        sizes = [len(length) for length, *_ in runs]
        self.key, self.longest = np.concatenate(keys), np.concatenate(longest)
        self.run_of = np.concatenate(run_of)  # each agent's run
        self.n = len(self.key)
        sentinel = np.array([[np.inf], [0.0], [0.0], [0.0], [-1.0], [0.0], [-1.0]])
        self._jacobi = np.concatenate([*jacobi, sentinel], axis=1)
        self._seq = np.concatenate([*seq, sentinel], axis=1)
        # The columns of each run's agents (old, new) and ego in the templates; each column's run.
        starts = np.cumsum([0, *sizes])[:-1]
        within = np.arange(self.n) - np.repeat(starts, sizes)
        self._j_old = within + np.repeat(starts + np.arange(self.runs), sizes)
        self._j_ego = starts + sizes + np.arange(self.runs)
        seq_starts = 2 * starts + np.arange(self.runs)
        self._s_old = within + np.repeat(seq_starts, sizes)
        self._s_new = self._s_old + np.repeat(sizes, sizes)
        self._s_ego = seq_starts + 2 * np.array(sizes)
        self._j_run = np.append(np.repeat(np.arange(self.runs), np.add(sizes, 1)), self.runs)
        self._s_run = np.append(np.repeat(np.arange(self.runs), 2 * np.array(sizes) + 1), self.runs)
        self._j_end, self._s_end = np.concatenate(jac_end), np.concatenate(seq_end)

    def jacobi(self, s, t, v, ego):
        """Everyone where they were (`ego`: station, offset, speed arrays, one per run)."""
        table = self._jacobi.copy()
        table[:3, self._j_old] = (s, t, v)
        table[:3, self._j_ego] = ego
        return self._sorted(table, self._j_run, self._j_old), self._j_end

    def sequential(self, s, t, v, new, ego):
        """Earlier agents at their `new` (station, offset, speed), later ones where they were."""
        table = self._seq.copy()
        table[:3, self._s_old] = (s, t, v)
        table[:3, self._s_new] = new
        table[:3, self._s_ego] = ego
        return self._sorted(table, self._s_run, self._s_old), self._s_end

    @staticmethod
    def _sorted(table, run, own):
        """The table sorted by (run, station), stably, and the column of the first entry of
        its run strictly ahead of each agent (`own`: its own entry's column, at its station):
        the start of the next group of equal (run, station) after its own entry's."""
        order = np.lexsort((table[0], run))
        table = table[:, order]
        at = np.empty_like(order)
        at[order] = np.arange(len(order))
        station = table[0]
        starts = np.flatnonzero((station[1:] != station[:-1]) | (run[1:] != run[:-1])) + 1
        return table, starts[np.searchsorted(starts, at[own], side="right")]

    def leaders(self, view, s, t, length, window_m: float = LANE_WINDOW_M):
        """(found, gap [m], leader speed [m/s]) per agent from a view (`jacobi`, `sequential`);
        `s`: the agents' stations where they were (their own entries' in the view)."""
        (table, first), end = view
        key, longest = self.key, self.longest
        found, best, speed, done = self._window(table, first, WINDOW, s, t, length, key, longest, end, window_m)
        if done.all():
            return found, best, speed
        rows, width = np.flatnonzero(~done), 4 * WINDOW
        while len(rows):  # not settled within the window: a wider one
            f, b, v, done = self._window(table, first[rows], width, s[rows], t[rows], length[rows], key[rows],
                                         longest[rows], end[rows], window_m)
            found[rows], best[rows], speed[rows] = f, b, v
            rows, width = rows[~done], 4 * width
        return found, best, speed

    @staticmethod
    def _window(table, first, width, s, t, length, key, longest, end, window_m):
        """`leaders` from the `width` entries ahead of each agent; `done` where no entry of
        its run beyond can be nearer (none left, or `neighbours.LeaderIndex`'s bound)."""
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
        beyond = first + width
        next_s = table[0, np.minimum(beyond, last)]
        done = (beyond >= end) | (next_s - s - 0.5 * (longest + length) > best + STOP_SLACK_M)
        return best < np.inf, best, speed, done


IDM_FIELDS = ("v0", "accel", "time_gap", "min_gap", "two_sqrt_ab")  # `IdmParams`' arrays


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
    return IdmParams(*(np.array([float(getattr(p, k)) for p in ps]) for k in IDM_FIELDS))


def idm_free(p: IdmParams, v) -> np.ndarray:
    """`behaviors.idm_free` of every agent."""
    return behaviors.idm_free(p, v, ARRAYS)


def idm_accel(p: IdmParams, v, free, found, gap, lead_speed) -> np.ndarray:
    """`behaviors.Idm.accel` of every agent [m/s^2] (`free`: `idm_free`; no leader where not `found`)."""
    g = np.where(found, gap, 1.0)
    return np.where(found, behaviors.idm_accel(p, v, free, g, lead_speed, ARRAYS), p.accel * free)
