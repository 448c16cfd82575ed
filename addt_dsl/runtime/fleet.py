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
    """The members as the agents of a batch of runs see them, as one table per view, kept
    sorted by (run, station): a block of entries per run, then `PAD` sentinel entries past
    every station that nobody sees. An entry's rows: station, offset, length, member index,
    and the keys lo..hi of the agents that see it (key = the run's base + road code * (n + 1)
    + agent index, the run's bases apart: an entry is seen only on its road, in its run);
    its speed is read only for the answer.

    The Jacobi view has each agent's old state (seen by all: an agent's own entry is never
    strictly ahead of it) and the ego. The sequential view has the old states seen by the
    agents before them, the new states seen by the agents after them, and the ego.

    Each view keeps its last order (entries sort the same from one step to the next but for
    the few that overtook): a call checks it and repairs it where an entry moved past
    another. Entries of equal (run, station) may sit in any order: the lookup's answer does
    not depend on it (the nearest gap, ties by member index, and the walk's bound). (A NaN
    station, which the agents' step never passes, gives a NaN gap where it falls within an
    agent's window, so there the answer depends on the window's width.)

    `runs`: per run (agents' lengths [m], their road codes, the ego's length [m], its road
    code); a single run is a batch of one."""

    PAD = WINDOW + 1  # sentinels: the first window and the entry after it stay in the table

    def __init__(self, runs):
        sizes = [len(length) for length, *_ in runs]
        self.runs, self.n = len(runs), sum(sizes)
        keys, longest, run_of, ego = [], [], [], []
        base_key = 0.0
        for r, (length, road, ego_length, ego_road) in enumerate(runs):
            n = len(length)
            base = base_key + road * (n + 1.0)
            keys.append(base + np.arange(n, dtype=float))  # each agent's own key
            ego_base = base_key + ego_road * (n + 1.0)
            ego.append((ego_length, n, ego_base, ego_base + n - 1))
            longest.append(np.full(n, max(float(length.max()), ego_length)))
            run_of.append(np.full(n, r))
            base_key += (max(int(road.max()), ego_road) + 1) * (n + 1.0)
        self.key, self.longest = np.concatenate(keys), np.concatenate(longest)
        self.run_of = np.concatenate(run_of)  # each agent's run
        length = np.concatenate([length for length, *_ in runs])
        within = np.concatenate([np.arange(n, dtype=float) for n in sizes])  # member index
        base = self.key - within
        last = base + np.repeat(np.add(sizes, -1.0), sizes)
        ego, pad = np.array(ego, dtype=float).reshape(-1, 4).T, np.array([[0.0], [-1.0], [0.0], [-1.0]])
        # Unsorted columns: the agents (old), [the agents (new),] the egos, the sentinels;
        # rows: length, member index, lo, hi.
        jacobi = np.hstack([(length, within, base, last), ego, np.repeat(pad, self.PAD, axis=1)])
        seq = np.hstack([(length, within, base, base + within - 1.0), (length, within, base + within + 1.0, last),
                         ego, np.repeat(pad, self.PAD, axis=1)])
        runs_ = np.arange(self.runs)
        self._jacobi = _View(jacobi, np.concatenate([self.run_of, runs_]), self.run_of, 1, self.PAD)
        self._seq = _View(seq, np.concatenate([self.run_of, self.run_of, runs_]), self.run_of, 2, self.PAD)
        self._pad = (np.full(self.PAD, np.inf), np.zeros(self.PAD))

    def jacobi(self, s, t, v, ego):
        """Everyone where they were (`ego`: station, offset, speed arrays, one per run)."""
        inf, zero = self._pad
        return self._jacobi.view(np.concatenate((s, ego[0], inf)), np.concatenate((t, ego[1], zero)),
                                 np.concatenate((v, ego[2], zero)))

    def sequential(self, s, t, v, new, ego):
        """Earlier agents at their `new` (station, offset, speed), later ones where they were."""
        inf, zero = self._pad
        return self._seq.view(np.concatenate((s, new[0], ego[0], inf)), np.concatenate((t, new[1], ego[1], zero)),
                              np.concatenate((v, new[2], ego[2], zero)))

    def leaders(self, view, s, t, length, window_m: float = LANE_WINDOW_M):
        """(found, gap [m], leader speed [m/s]; 0 where none) per agent from a view (`jacobi`,
        `sequential`); `s`: the agents' stations where they were (their own entries' in the view)."""
        first, end, copies = view[0], view[-2], view[-1]
        key, longest = self.key, self.longest
        width = max(1, WINDOW * copies // 2)  # (the Jacobi view has half the sequential one's entries)
        found, best, speed, done = self._window(view, first, width, s, t, length, key, longest, end, window_m)
        if done.all():
            return found, best, speed
        rows, width = np.flatnonzero(~done), 4 * width
        while len(rows):  # not settled within the window: a wider one
            f, b, v, done = self._window(view, first[rows], width, s[rows], t[rows], length[rows], key[rows],
                                         longest[rows], end[rows], window_m)
            found[rows], best[rows], speed[rows] = f, b, v
            rows, width = rows[~done], 4 * width
        return found, best, speed

    def _window(self, view, first, width, s, t, length, k, longest, end, window_m):
        """`leaders` from the `width` entries ahead of each agent; `done` where no entry of
        its run beyond can be nearer (none left, or `neighbours.LeaderIndex`'s bound).

        Arrays are (window entry, agent): the reductions over the window run along
        contiguous rows (numpy's quick path; along short rows it is ~20x slower)."""
        _, station, offset, speed, (el, em, lo, hi), *_ = view
        cols = first + np.arange(width)[:, None]
        beyond = first + width
        if width >= self.PAD:  # (the sentinels cover a first window only)
            last = len(station) - 1
            cols, beyond = np.minimum(cols, last), np.minimum(beyond, last)
        hidden = (lo[cols] > k) | (k > hi[cols]) | outside_lane(offset[cols], t, window_m)
        g = np.where(hidden, np.inf, bumper_gap(station[cols], el[cols], s, length))
        best = g.min(axis=0)
        found = best < np.inf
        tied = g == best  # (where one is found, only seen entries have its gap)
        sp = speed[cols]
        lead = np.where(tied, sp, -np.inf).max(axis=0)  # the speed of the one entry with the least gap
        several = found & (tied.sum(axis=0) > 1)
        if several.any():  # equal gaps: the least member index
            r = np.flatnonzero(several)
            col = np.where(tied[:, r], em[cols[:, r]], np.inf).argmin(axis=0)
            lead[r] = sp[col, r]
        done = (beyond >= end) | (station[beyond] - s - 0.5 * (longest + length) > best + STOP_SLACK_M)
        return found, best, np.where(found, lead, 0.0), done


class _View:
    """One view's sorted order over its unsorted columns (`const`: the rows that do not
    change, `run`: each column's run; each agent's own entry is column `agent`), kept from
    call to call."""

    def __init__(self, const, run, run_of, copies, pad):
        self.const, self.run = const, np.concatenate([run, np.full(pad, run.max(initial=-1) + 1)])
        counts = np.bincount(run, minlength=run_of.max(initial=-1) + 1)
        self.end = np.cumsum(counts)[run_of]  # each agent's run's block ends before this sorted entry
        self.run_sorted = np.sort(self.run)  # (in every order sorted by (run, station))
        self.same_run = self.run_sorted[1:] == self.run_sorted[:-1]
        self.run_change = ~self.same_run
        self.n, self.copies = len(run_of), copies
        self.one_run = len(counts) == 1
        self.order = None

    def view(self, station, offset, speed):
        """(first entry strictly ahead of each agent: the start of the next group of equal
        (run, station) after its own entry's; station, offset, speed, const rows in sorted
        order; each agent's run's end; entries per agent)."""
        order = self.order
        if order is not None:
            st = station[order]
            # still sorted? (`not >=`: a NaN station is out of order, as lexsort puts it last)
            if (~(st[1:] >= st[:-1]) & self.same_run).any():
                order = order[np.lexsort((st, self.run_sorted))]  # repair (nearly sorted: quick)
        else:
            order = np.lexsort((station, self.run))
        if order is not self.order:
            self.order = order
            if not self.one_run:
                at = np.empty_like(order)
                at[order] = np.arange(len(order))
                self.own = at[:self.n]
            self.const_sorted = tuple(self.const[:, order])  # (contiguous rows)
            st = station[order]
        if self.one_run:  # (its entries, then the sentinels, ascending: bisect the stations)
            first = st.searchsorted(station[:self.n], side="right")
        else:
            starts = np.flatnonzero((st[1:] != st[:-1]) | self.run_change) + 1
            first = starts[np.searchsorted(starts, self.own, side="right")]
        return first, st, offset[order], speed[order], self.const_sorted, self.end, self.copies


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
