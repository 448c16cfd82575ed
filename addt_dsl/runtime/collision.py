"""Collisions and clearances: each actor's least separation from every other box, and a
`collision` event when two boxes start to overlap.

Two actors' separation [m] is defined by `_pair`: their centres' distance less their
half-diagonals when that is over 5 m, else `world.separation` (the separating axis test).
`_clearances` is one compiled kernel over every run of a batch (the runs' actors one after
another): each actor's least separation over the pairs of its run, and the pairs that
touch. It gives the figures of visiting every pair with `_pair`, evaluating `_pair` only
where a cheaper distance cannot settle the least (its broad phase).
"""

from __future__ import annotations

import math
from itertools import accumulate

import numpy as np

from addt_dsl.kernel import hypot, kernel
from addt_dsl.lru import LruCache
from addt_dsl.runtime.trace import Event
from addt_dsl.runtime.world import separation

# Broad-phase slack [m]: sqrt(dx^2 + dy^2) differs from hypot by ulps, far below this.
_BROAD_SLACK_M = 1e-6
_NO_CLEARANCE_M = 1e3  # recorded for an actor without a finite separation (alone in its run)


def clearances(rows, names, sizes, run, t_now) -> bool:
    """One run's clearances (`clearances_batch` of a batch of one)."""
    return clearances_batch([(rows, names, sizes, run, t_now)])[0]


def clearances_batch(items) -> list[bool]:
    """Over a batch, per run (rows, names, sizes, run, t_now): each actor's clearance into
    the last column of `rows` (float64, a row per actor in names' order, x, y and heading
    its first three columns: a step's rows of `phases.Record`); a collision event when two
    boxes start to overlap (any pair, agents included); `sizes`: a row (length, width) [m]
    per actor. Whether each run's ego is in a collision (the run ends).

    Each actor's clearance is its least `_pair` separation over the pairs of its run, 1e3 m
    when there is none finite; every run of the batch in one call of `_clearances`."""
    if len(items) == 1:
        rows, sizes = items[0][0], items[0][2]
        first = _first((len(rows),))
    else:
        first = _first(tuple([len(item[0]) for item in items]))
        rows = np.concatenate([item[0] for item in items])
        sizes = np.concatenate([item[2] for item in items])
    collided = clearances_rows(rows, first, _every(len(items)), sizes, [(item[1], item[3], item[4]) for item in items])
    if len(items) > 1:
        for item, lo, hi in zip(items, first.tolist(), first[1:].tolist()):
            item[0][:, -1] = rows[lo:hi, -1]
    return collided


def clearances_rows(rows, first, live, sizes, runs) -> list[bool]:
    """`clearances_batch` on a step's rows of a whole batch (run k's actors are rows
    `first[k]` to `first[k + 1]`, sizes likewise), for the runs `live` (their indices k,
    int64; `runs`: for each, (its names, its run, t_now)): the clearances in place, one
    kernel call; whether each of those runs' ego is in a collision."""
    touch = np.empty((len(rows) + 8, 3), dtype=np.int64)
    found = _clearances(first, live, rows, sizes, touch)
    if found > len(touch):  # more contacts than room: again with room for all
        touch = np.empty((found, 3), dtype=np.int64)
        _clearances(first, live, rows, sizes, touch)
    collided = [False] * len(runs)
    pairs: dict[int, list] = {}
    if found:
        for j, a, b in touch[:found].tolist():  # in all-pairs order, run by run
            pairs.setdefault(j, []).append((a, b))
    for j, item in enumerate(runs):
        if j in pairs:
            collided[j] = _contacts(item, pairs[j])
        elif item[1].contacts:
            item[1].contacts = set()
    return collided


def _every(n: int) -> np.ndarray:
    """0 .. n - 1 (read only: shared)."""
    every = _EVERY.get(n)
    if every is None:
        every = np.arange(n, dtype=np.int64)
        every.flags.writeable = False
        _EVERY.put(n, every)
    return every


_EVERY: LruCache[int, np.ndarray] = LruCache(64)


# runs' actor counts -> each run's first actor (and the total); batches lose runs as they
# end: a few keys each
_FIRSTS: LruCache[tuple, np.ndarray] = LruCache(256)


def _first(counts: tuple) -> np.ndarray:
    """Each run's first actor in the batch's rows, then their count (read only: shared)."""
    first = _FIRSTS.get(counts)
    if first is None:
        first = np.array(list(accumulate(counts, initial=0)), dtype=np.int64)
        first.flags.writeable = False
        _FIRSTS.put(counts, first)
    return first


def _contacts(item, pairs) -> bool:
    """A run's (names, run, t_now) `collision` events of the pairs (i, j) that touch now and
    did not before; whether the ego is in one."""
    names, run, t_now = item
    collided = False
    touching = set()
    for i, j in pairs:
        a, b = names[i], names[j]
        touching.add((a, b))
        if (a, b) not in run.contacts:
            run.events.append(Event(t_now, "collision", {"actors": [a, b]}))
        if a == "ego" or b == "ego":
            collided = True
    run.contacts = touching
    return collided


@kernel
def _pair(xa, ya, ca, sa, la, wa, ra, xb, yb, cb, sb, lb, wb, rb):
    """Two actors' separation [m]: their centres' distance (`math.hypot`'s) less their
    half-diagonals `ra + rb` when that is over 5 m (cheap, a lower bound of the boxes'
    gap), else the boxes' (`world.separation`, from each heading's cosine and sine)."""
    dist = hypot(xa - xb, ya - yb)
    r = ra + rb
    if dist > r + 5.0:
        return dist - r
    return separation(xb - xa, yb - ya, ca, sa, cb, sb, la, wa, lb, wb)


@kernel
def _exact(a, b, x, y, heading, length, width, reach, cos_h, sin_h, trig):
    """`_pair` of actors a and b; their headings' cosine and sine computed once a call
    (`trig`: which are)."""
    for c in (a, b):
        if not trig[c]:
            cos_h[c], sin_h[c], trig[c] = math.cos(heading[c]), math.sin(heading[c]), True
    return _pair(x[a], y[a], cos_h[a], sin_h[a], length[a], width[a], reach[a],
                 x[b], y[b], cos_h[b], sin_h[b], length[b], width[b], reach[b])


@kernel
def _clearances(first, live, rows, sizes, touch):
    """The clearances of the runs `live[0]`, `live[1]`, ...: run k's actors are rows
    `first[k]` to `first[k + 1]` of `rows` (x, y, heading its first columns) and `sizes`
    (length, width); into the last column of `rows` each actor's least `_pair` separation
    over the pairs of its run (1e3 when none is finite), into `touch` the pairs that touch
    (separation <= 0) as (j, i, k) of run live[j] in all-pairs order (i < k, actors counted
    from the run's first), as many as fit. Returns how many pairs touch.

    The figures are those of visiting every pair in order (a < b) with `_pair` and keeping
    a new least only when it is less. A pair whose plain distance d = sqrt(dx^2 + dy^2) is
    over its reach + 5 m by more than its slack s = 1e-6 (1 + d) m is far: `_pair` gives
    its `hypot` distance less the reach, which differs from d less the reach by ulps, far
    less than s. A first pass takes far pairs' plain figure, the others `_pair`: each
    actor's first least L, set by a pair of slack t (0 when exact), is at least its exact
    least E less t. A far pair whose plain figure is over L + t + s cannot be the actor's
    least (its exact figure is over L + t >= E). Actors with a far pair within that bound
    (`low`: the least plain figure less slack of its far pairs) visit their pairs again in
    order, with `_pair` for those within it; the others' L is E."""
    x, y, heading, length, width = rows[:, 0], rows[:, 1], rows[:, 2], sizes[:, 0], sizes[:, 1]
    n = rows.shape[0]
    clear = rows[:, rows.shape[1] - 1]
    reach = np.empty(n)
    cos_h = np.empty(n)
    sin_h = np.empty(n)
    trig = np.zeros(n, dtype=np.bool_)  # cos_h, sin_h computed (when a box test needs them)
    tol = np.empty(n)  # the slack of the pair that set each actor's first least
    low = np.empty(n)  # each actor's least plain figure less slack over its far pairs
    found = 0
    for j in range(live.size):
        lo, hi = first[live[j]], first[live[j] + 1]
        for a in range(lo, hi):
            reach[a] = 0.5 * hypot(length[a], width[a])
            clear[a], tol[a], low[a] = math.inf, 0.0, math.inf
        for a in range(lo, hi):
            xa, ya, ra = x[a], y[a], reach[a]
            clear_a, tol_a, low_a = clear[a], tol[a], low[a]  # (a's own, in registers along its pairs)
            for b in range(a + 1, hi):
                dx, dy = xa - x[b], ya - y[b]
                d = math.sqrt(dx * dx + dy * dy)
                r = ra + reach[b]
                slack = _BROAD_SLACK_M * (1.0 + d)
                if d > r + 5.0 + slack:  # far (so not inf, not NaN)
                    sep = d - r
                    q = sep - slack
                    if q < low_a:
                        low_a = q
                    if q < low[b]:
                        low[b] = q
                else:
                    slack = 0.0
                    sep = _exact(a, b, x, y, heading, length, width, reach, cos_h, sin_h, trig)
                    if sep <= 0.0:
                        if found < touch.shape[0]:
                            touch[found, 0], touch[found, 1], touch[found, 2] = j, a - lo, b - lo
                        found += 1
                if sep < clear_a:
                    clear_a, tol_a = sep, slack
                if sep < clear[b]:
                    clear[b], tol[b] = sep, slack
            clear[a], tol[a], low[a] = clear_a, tol_a, low_a
        for c in range(lo, hi):
            bound = clear[c] + tol[c]
            if not low[c] <= bound:  # no far pair can be c's least: it has it
                continue
            least = math.inf  # c's pairs again, in all-pairs order (those with a < c first)
            for other in range(lo, hi):
                if other == c:
                    continue
                a, b = (other, c) if other < c else (c, other)
                dx, dy = x[a] - x[b], y[a] - y[b]
                d = math.sqrt(dx * dx + dy * dy)
                r = reach[a] + reach[b]
                slack = _BROAD_SLACK_M * (1.0 + d)
                if d > r + 5.0 + slack and d - r > bound + slack:
                    sep = d - r
                else:
                    sep = _exact(a, b, x, y, heading, length, width, reach, cos_h, sin_h, trig)
                if sep < least:
                    least = sep
            clear[c] = least
        for a in range(lo, hi):
            c = clear[a]
            clear[a] = c if math.isfinite(c) else _NO_CLEARANCE_M
    return found
