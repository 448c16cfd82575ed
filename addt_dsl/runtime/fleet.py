"""Car-following agents stepped as arrays: the leader lookup and the IDM step of every
agent at once (numpy over agents), with the floats of the per-agent code.

The loop steps agents one after another in declaration order, so agent i reads the
agents before it where they have already moved this step (their new station, offset
and speed) and those after it where they were. `leaders` answers that lookup for every
agent at once from a *view*: each agent's old state, optionally the new states, and the
ego. Its answer for agent i is `neighbours.leader_scan` over the members as agent i sees
them: the nearest member ahead on its road within the lane window, the first in member
order on equal gaps (agents in declaration order, then the ego).

`step_idm` solves the sequential step as a fixed point: it steps every agent against
the old states (what agent i sees when no earlier agent is its leader), then asks the
lookup again with the earlier agents moved; when no answer changes, the new states are
those of the sequential loop (agent i's answer depends only on agents before it, so the
fixed point is unique). Agents declared behind their leaders settle in one check; a
chain declared front to back would need a round per car and is left to the scalar loop.

Bit for bit: +, -, *, /, sqrt and comparisons in numpy round as Python's floats do, in
the same order of operations; powers stay Python's (`pow`, libm), as numpy's may not.
"""

from __future__ import annotations

import math
from itertools import repeat

import numpy as np

from addt_dsl.runtime.neighbours import LANE_WINDOW_M, STOP_SLACK_M

WINDOW = 12  # view entries examined per agent at first (widened where not enough) [-]
MAX_ROUNDS = 3  # fixed-point checks before a step is left to the scalar loop


def _select(mask, gap, member, speed):
    """Per row: (found, least gap, its speed) among masked columns; equal gaps go to the
    least member index."""
    g = np.where(mask, gap, np.inf)
    best = g.min(axis=1)
    tied = mask & (g == best[:, None])
    col = np.where(tied, member, np.iinfo(np.int64).max).argmin(axis=1)
    rows = np.arange(len(best))
    return tied.any(axis=1), best, speed[rows, col]


def view(agents, ego, new=None) -> tuple:
    """Entries of the view: agents' old states (seen by the agents after them, or by every
    other agent when `new` is None), their new states (seen by the agents after them) and
    the ego (seen by all). `agents` = (s, t, speed, length, road) arrays, `ego` the same as
    floats; `new` = (s, t, speed) arrays."""
    s, t, v, length, road = agents
    n = len(s)
    idx = np.arange(n)
    parts = [(s, t, v, length, road, idx)]
    if new is not None:
        parts.append((new[0], new[1], new[2], length, road, idx))
    parts.append(tuple(np.array([x]) for x in (*ego, n)))
    return (*(np.concatenate(col) for col in zip(*parts)), new is None)


def leaders(agents, entries, window_m: float = LANE_WINDOW_M):
    """(found, gap [m], leader speed [m/s]) per agent from a view (`view`)."""
    s = agents[0]
    es, el = entries[0], entries[3]
    order = np.argsort(es, kind="stable")
    ss = es[order]
    first = np.searchsorted(ss, s, side="right")  # the first entry strictly ahead
    longest = float(el.max())
    rows = np.arange(len(s))
    found, best, speed = np.zeros(len(s), dtype=bool), np.full(len(s), np.inf), np.zeros(len(s))
    width = WINDOW
    while len(rows):
        f, b, v, done = _window(rows, first[rows], width, agents, entries, order, ss, longest, window_m)
        found[rows], best[rows], speed[rows] = f, b, v
        rows, width = rows[~done], 4 * width  # not settled within the window: a wider one
    return found, best, speed


def _window(rows, first, width, agents, entries, order, ss, longest, window_m):
    """`leaders` for agents `rows` from the `width` entries ahead of each; `done` where no
    entry beyond the window can be nearer (none left, or the index's stopping bound)."""
    s, t, _, length, road = (a[rows] for a in agents)
    es, et, ev, el, er, em, jacobi = entries
    n, e_count = len(agents[0]), len(es)
    cols = first[:, None] + np.arange(width)
    inside = cols < e_count
    e = order[np.minimum(cols, e_count - 1)]
    me = em[e]
    agent = rows[:, None]
    if jacobi:
        seen = me != agent
    else:  # old entries (the first n) by agents before them, new ones by agents after them
        seen = np.where(e < n, agent < me, agent > me) | (me == n)
    gap = (es[e] - s[:, None]) - 0.5 * (el[e] + length[:, None])
    mask = inside & seen & (er[e] == road[:, None]) & ~(np.abs(et[e] - t[:, None]) > window_m) \
        & (es[e] > s[:, None])
    found, best, speed = _select(mask, gap, me, ev[e])
    last = first + width
    beyond = last < e_count
    bound = ss[np.minimum(last, e_count - 1)] - s - 0.5 * (longest + length)
    done = ~beyond | (found & (bound > best + STOP_SLACK_M))
    return found, best, speed, done


class IdmParams:
    """Per-agent IDM settings as arrays, with the per-agent constants of `Idm.accel`."""

    def __init__(self, settings: list[dict]):
        col = lambda key: np.array([float(p[key]) for p in settings])  # noqa: E731
        self.v0 = np.array([max(p["speed"], 0.1) for p in settings], dtype=float)
        self.accel = col("accel")
        self.time_gap = col("time_gap")
        self.min_gap = col("min_gap")
        self.two_sqrt_ab = np.array([2.0 * math.sqrt(p["accel"] * p["decel"]) for p in settings])


def idm_accel(p: IdmParams, v, found, gap, lead_speed) -> np.ndarray:
    """`behaviors.Idm.accel` of every agent [m/s^2]."""
    n = len(v)
    free = 1.0 - np.fromiter(map(pow, (v / p.v0).tolist(), repeat(4, n)), float, n)
    dv = v - lead_speed
    inner = v * p.time_gap + v * dv / p.two_sqrt_ab
    s_star = p.min_gap + np.where(inner > 0.0, inner, 0.0)
    g = np.where(found, gap, 1.0)
    g = np.where(0.1 > g, 0.1, g)
    q = (s_star / g).tolist()
    ratio2 = np.fromiter(map(pow, q, repeat(2, n)), float, n)
    return np.where(found, p.accel * (free - ratio2), p.accel * free)
