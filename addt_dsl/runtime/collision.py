"""Collisions and clearances: each actor's least separation from every other box, and a
`collision` event when two boxes start to overlap.

`_all_pairs` visits every pair and defines two actors' separation [m] (their centres'
distance less their half-diagonals when that is over 5 m, else `world.box_separation`);
`_broad_phase` gives the same figures for many actors (of every run of a batch at once)
from a numpy broad phase,
evaluating exactly (`_exact_separations`, the same formulas over arrays: `world.separation`)
only the pairs that can matter.
"""

from __future__ import annotations

import math
from itertools import accumulate

import numpy as np

from addt_dsl.runtime.trace import Event
from addt_dsl.runtime.world import box_separation, separation


def clearances(out, names, x, y, heading, length, width, run, t_now) -> bool:
    """One run's clearances (`clearances_batch` of a batch of one)."""
    return clearances_batch([(out, names, x, y, heading, length, width, run, t_now)])[0]


def clearances_batch(items) -> list[bool]:
    """Over a batch, per run (out, names, x, y, heading, length, width, run, t_now): record
    each actor's clearance in `out` (names' order; x, y, heading, length and width are
    arrays in that order); a collision event when two boxes start to overlap (any pair,
    agents included). Whether each run's ego is in a collision (the run ends).

    Each actor's clearance is its least separation over all pairs of its run (`_all_pairs`).
    A numpy broad phase over the pairs of every run at once (`_broad_phase`) finds the
    pairs that can matter (those near enough for the exact test, and those whose
    approximate separation is within a tolerance of an actor's least); only these are
    evaluated, with the arithmetic of the all-pairs loop (elementwise in numpy, hypot, sin
    and cos from `math`), so the figures are those of visiting every pair."""
    found = _separations(items)
    return [_contacts(item, *pairs) for item, pairs in zip(items, found)]


def _contacts(item, i, j, sep, clear) -> bool:
    """A run's clearances into `out`, `collision` events of pairs that start to touch."""
    out, names, run, t_now = item[0], item[1], item[7], item[8]
    collided = False
    touching = set()
    for p in [p for p, value in enumerate(sep.tolist() if isinstance(sep, np.ndarray) else sep)
              if value <= 0.0]:  # in all-pairs order
        a, b = names[i[p]], names[j[p]]
        touching.add((a, b))
        if (a, b) not in run.contacts:
            run.events.append(Event(t_now, "collision", {"actors": [a, b]}))
        if a == "ego" or b == "ego":
            collided = True
    run.contacts = touching
    out[:] = [c if math.isfinite(c) else 1e3 for c in (clear.tolist() if isinstance(clear, np.ndarray) else clear)]
    return collided


def _floats(values) -> list:
    return values.tolist() if isinstance(values, np.ndarray) else values


def _all_pairs(x, y, heading, length, width, reach=None):
    """Every pair one by one: (i, j, separation) of the pairs that touch (separation <= 0),
    in all-pairs order, and each actor's least separation; `reach`: each actor's
    half-diagonal [m] (computed when not given).

    The separation of two actors' boxes [m] is defined here: their centre distance less
    their half-diagonals when that is over 5 m (cheap, a lower bound of the boxes' gap),
    else exact (`world.box_separation`, the separating axis test)."""
    cols = (x, y, heading, length, width)
    # (the loop's few actors come as lists: no conversion)
    boxes = list(zip(*cols) if all(type(v) is list for v in cols) else zip(*map(_floats, cols)))
    if reach is None:
        reach = [0.5 * math.hypot(b[3], b[4]) for b in boxes]
    n = len(boxes)
    clear = [math.inf] * n
    iu, ju, seps = [], [], []
    for a in range(n):
        box_a, reach_a = boxes[a], reach[a]
        xa, ya = box_a[0], box_a[1]
        for b in range(a + 1, n):
            box_b = boxes[b]
            dist = math.hypot(xa - box_b[0], ya - box_b[1])
            r = reach_a + reach[b]
            sep = dist - r if dist > r + 5.0 else box_separation(box_a, box_b)
            if sep < clear[a]:
                clear[a] = sep
            if sep < clear[b]:
                clear[b] = sep
            if sep <= 0.0:
                iu.append(a)
                ju.append(b)
                seps.append(sep)
    return iu, ju, seps, clear


# Broad-phase slack [m]: sqrt(dx^2 + dy^2) differs from math.hypot by ulps, far below this.
_BROAD_SLACK_M = 1e-6
_FEW_BOX_TESTS = 8  # up to this many box tests one by one, more as arrays
ALL_PAIRS_MAX = 24  # up to this many actors every pair one by one (measured: quicker than numpy)
BROAD_PAIRS = 8192  # pairs in one broad phase over runs (more: slower per pair, arrays out of cache)


def _separations(items) -> list:
    """Per run (i, j, separation [m]) of the pairs near enough for the box test (every
    contact is among them), in all-pairs order (i < j over its names), and each actor's
    clearance: its least separation over all pairs (`_all_pairs` when a pose is not finite
    or there are few actors, else the batch's `_broad_phase`)."""
    found: list = [None] * len(items)
    many = []
    for k, (_, names, x, y, heading, length, width, run, _) in enumerate(items):
        n = len(names)
        if n <= ALL_PAIRS_MAX:  # few actors: every pair, one by one, is quicker
            reach = getattr(run, "clearance_reach", None)
            if reach is None or len(reach) != n:  # sizes are fixed: once per run
                reach = run.clearance_reach = [0.5 * math.hypot(a, b) for a, b in zip(_floats(length), _floats(width))]
            found[k] = _all_pairs(x, y, heading, length, width, reach)
            continue
        x, y, heading = np.asarray(x, dtype=float), np.asarray(y, dtype=float), np.asarray(heading, dtype=float)
        # A pose not finite (or so far out that squares overflow): every pair.
        if not ((np.abs(x) < 1e100).all() and (np.abs(y) < 1e100).all() and np.isfinite(heading).all()):
            found[k] = _all_pairs(x, y, heading, length, width)
            continue
        pairs = getattr(run, "clearance_pairs", None)
        if pairs is None or len(pairs[0]) != n * (n - 1) // 2:  # sizes are fixed: once per run
            reach = np.array([0.5 * math.hypot(a, b) for a, b in zip(length.tolist(), width.tolist())])
            iu, ju = np.triu_indices(n, 1)
            r = reach[iu] + reach[ju]
            # For each actor's least (`_least`): where each actor's pairs as i start (iu is
            # sorted), the pairs ordered by j and where each actor's start.
            by_j = np.argsort(ju, kind="stable")
            i_starts = np.flatnonzero(np.r_[True, iu[1:] != iu[:-1]])
            j_starts = np.flatnonzero(np.r_[True, ju[by_j][1:] != ju[by_j][:-1]])
            run.clearance_pairs = pairs = (iu, ju, r, r + 5.0, by_j, i_starts, j_starts)
        many.append((k, x, y, heading, length, width, pairs))
    start = 0
    while start < len(many):  # runs of at most ~BROAD_PAIRS pairs at once (their arrays stay in cache)
        end, pairs = start + 1, len(many[start][-1][0])
        while end < len(many) and pairs + len(many[end][-1][0]) <= BROAD_PAIRS:
            pairs += len(many[end][-1][0])
            end += 1
        for (k, *_), answer in zip(many[start:end], _broad_phase([m[1:] for m in many[start:end]])):
            found[k] = answer
        start = end
    return found


def _broad_phase(runs) -> list:
    """`_separations` of runs with many actors, per run (x, y, heading, length, width,
    its pairs (i, j, reach sum, reach sum + 5 m)): every run's pairs as one array."""
    sizes = [len(x) for x, *_ in runs]
    counts = [len(p[0]) for *_, p in runs]
    first = list(accumulate(sizes[:-1], initial=0))  # each run's first actor
    at = list(accumulate(counts[:-1], initial=0))  # and first pair
    x, y, heading, length, width = (_join([run[c] for run in runs]) for c in range(5))
    iu, ju = (_join([p[c] + lo for (*_, p), lo in zip(runs, first)]) for c in range(2))
    r, r_exact = (_join([p[c] for *_, p in runs]) for c in (2, 3))
    by_j, i_starts, j_starts = (_join([p[c] + lo for (*_, p), lo in zip(runs, at)]) for c in (4, 5, 6))
    segments = (i_starts, iu[i_starts], by_j, j_starts, ju[by_j[j_starts]])
    dx, dy = x[iu] - x[ju], y[iu] - y[ju]
    d = np.sqrt(dx * dx + dy * dy)
    slack = _BROAD_SLACK_M * (1.0 + d)
    close = d <= r_exact + slack
    near = np.flatnonzero(close)  # the exact test may apply
    sep = d - r
    trig = []  # per actor (cos, sin) of the heading, from math, when a box test needs them
    sep[near] = _exact_separations(near, dx, dy, iu, ju, r, r_exact, x, y, heading, length, width, trig)
    least = _least(len(x), sep, segments)
    # Pairs whose approximate separation is within the slack of an actor's least: exact
    # too. The others are farther than every actor's least by more than the slack, so the
    # least over them then is the least over exact values.
    extra = np.flatnonzero(~close & (sep <= np.maximum(least[iu], least[ju]) + 2.0 * slack))
    if len(extra):
        exact = sep.copy()
        exact[extra] = _exact_separations(extra, dx, dy, iu, ju, r, r_exact, x, y, heading, length, width, trig)
        least = _least(len(x), exact, segments)
    if len(runs) == 1:
        return [(iu[near], ju[near], sep[near], least)]
    # Each run's share: its near pairs (in its all-pairs order) and its actors.
    cut = np.searchsorted(near, at[1:]).tolist()
    out = []
    for lo, n, rows in zip(first, sizes, np.split(near, cut)):
        out.append((iu[rows] - lo, ju[rows] - lo, sep[rows], least[lo:lo + n]))
    return out


def _join(arrays: list) -> np.ndarray:
    return arrays[0] if len(arrays) == 1 else np.concatenate(arrays)


def _least(n: int, sep, segments) -> np.ndarray:
    """Each of `n` actors' least separation over the pairs it is in [m]: the least of the
    segment of pairs where it is i (pairs in all-pairs order), then of those where it is j
    (pairs ordered by j); `segments`: (the i segments' starts, their actors, the order by j,
    the j segments' starts, their actors)."""
    i_starts, i_actor, by_j, j_starts, j_actor = segments
    least = np.full(n, np.inf)
    least[i_actor] = np.minimum.reduceat(sep, i_starts)
    least[j_actor] = np.minimum(least[j_actor], np.minimum.reduceat(sep[by_j], j_starts))
    return least


def _exact_separations(p, dx, dy, iu, ju, r, r_exact, x, y, heading, length, width, trig) -> np.ndarray:
    """`_all_pairs`' separation of pairs `p`, bit for bit: math.hypot of the centres, and where
    they are within reach + 5 m the separating-axis test of `world.box_separation`,
    written elementwise in its order."""
    dist = np.fromiter(map(math.hypot, dx[p].tolist(), dy[p].tolist()), float, len(p))
    out = dist - r[p]
    boxed = np.flatnonzero(~(dist > r_exact[p]))
    if 0 < len(boxed) <= _FEW_BOX_TESTS:  # a few: one by one (numpy's calls cost more)
        cols = [_floats(v) for v in (x, y, heading, length, width)]
        for k, a, b in zip(boxed.tolist(), iu[p[boxed]].tolist(), ju[p[boxed]].tolist()):
            out[k] = box_separation(tuple(c[a] for c in cols), tuple(c[b] for c in cols))
    elif len(boxed):
        if not trig:
            hl = heading.tolist()
            trig[:] = [np.fromiter(map(math.cos, hl), float, len(hl)), np.fromiter(map(math.sin, hl), float, len(hl))]
        cos_h, sin_h = trig
        a, b = iu[p[boxed]], ju[p[boxed]]
        out[boxed] = separation(x[b] - x[a], y[b] - y[a], cos_h[a], sin_h[a], cos_h[b], sin_h[b],
                                length[a], width[a], length[b], width[b], _maximum)
    return out


def _maximum(a, b, c, d) -> np.ndarray:
    """`max` of four arrays, elementwise, in `max`'s order (finite values)."""
    return np.maximum(np.maximum(np.maximum(a, b), c), d)
