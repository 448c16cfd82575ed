"""The agents' longitudinal step as one compiled kernel (`step`): every agent of a batch's
runs, with the floats of the per-agent loop.

The loop steps a run's agents one after another in declaration order: agent i takes its
behaviour's acceleration and moves (`behaviors.advance`); a car-following agent first finds
its leader (`neighbours.LeaderIndex`: the nearest member strictly ahead on its road within
the lane window, the first in member order on equal gaps; members: the agents in
declaration order, then the ego) among the agents before it where they have already moved
this step and those after it where they were. `step` does exactly that for the behaviours
whose acceleration is a law of the agent's own state and fixed settings
(`behaviors.LAWS`, compiled in: IDM, tracking a speed, braking): per run, the run's members
in a list sorted by station, agent i's leader found by bisecting it and walking ahead while
a nearer gap is still possible (`LeaderIndex.leader`'s walk, bound and tie rule), agent i
moved to its new place in the list before agent i + 1 looks (`LeaderIndex.moved`); with a
non-finite station among the members, the scan of every member (`neighbours.leader_scan`),
as the index does.

Bit for bit: the kernel's +, -, *, /, sqrt and comparisons are Python's floats', `min` and
`max` written as the comparisons Python's make; powers are the C library's (`kernel.pow`).
"""

from __future__ import annotations

import math

import numpy as np

from addt_dsl.kernel import bisect_left, bisect_right, kernel
from addt_dsl.runtime.behaviors import (LAW_BRAKE, LAW_IDM, LAW_PARAMS, LAW_TRACK, brake_accel, idm_accel, idm_free,
                                        speed_tracking)
from addt_dsl.runtime.neighbours import STOP_SLACK_M


def law_params(laws: list[tuple[int, tuple]]) -> tuple[np.ndarray, np.ndarray]:
    """Per-agent laws (`behaviors.Behavior.array_law`'s (law, settings) of each) as `step`'s
    `law` codes and `params` rows (`LAW_PARAMS` x agents; rows past a law's settings 1.0,
    never read)."""
    code = np.array([law for law, _ in laws], dtype=np.int64)
    params = np.ones((LAW_PARAMS, len(laws)))
    for i, (_, values) in enumerate(laws):
        params[:len(values), i] = values
    return code, params


@kernel
def step(lo, cells, flat, placed, t_new, law, params, road, length, ego, ego_road, ego_length, dt, window_m,
         done):
    """One step of every agent of the runs: run r's agents are rows lo[r]:lo[r + 1] of the
    per-agent arrays, in declaration order, their state in `flat` (`agent_arrays`' fields
    x slots) at slots `cells`, moved there in place. Per agent: `t_new` its offset after the
    step [m] (lane change profile), `law` its behaviour's law (`behaviors.LAWS`; none: its
    acceleration is 0), `params` the law's settings (`law_params`), `road` its road's code,
    `length` [m].
    Per run: `ego` (station [m], offset [m], speed [m/s]) run after run, `ego_road`,
    `ego_length` [m], `dt` [s]. `done[r]` False where run r is left to
    the per-agent loop, nothing of it moved: an agent teleported this step (`placed`, over
    the slots), or a station or offset of its agents or its ego not finite. Returns how many
    runs are left."""
    runs = lo.size - 1
    left = 0
    width = 1
    for r in range(runs):
        width = max(width, lo[r + 1] - lo[r] + 1)
    ms, mt, mv, ml = np.empty(width), np.empty(width), np.empty(width), np.empty(width)
    mroad = np.empty(width, dtype=np.int64)
    keys, ids = np.empty(width), np.empty(width, dtype=np.int64)
    for r in range(runs):
        a, n = lo[r], lo[r + 1] - lo[r]
        ok = math.isfinite(ego[3 * r]) and math.isfinite(ego[3 * r + 1])
        for i in range(n):
            c = cells[a + i]
            if placed[c] or not (math.isfinite(flat[0, c]) and math.isfinite(flat[1, c])):
                ok = False
        done[r] = ok
        if not ok:
            left += 1
            continue
        # The members as agent 0 sees them: the agents where they were, then the ego.
        longest = ego_length[r]
        for i in range(n):
            c = cells[a + i]
            ms[i], mt[i], mv[i], ml[i], mroad[i] = flat[0, c], flat[1, c], flat[2, c], length[a + i], road[a + i]
            if ml[i] > longest:
                longest = ml[i]
        ms[n], mt[n], mv[n], ml[n], mroad[n] = ego[3 * r], ego[3 * r + 1], ego[3 * r + 2], ego_length[r], ego_road[r]
        scan = False  # (a non-finite station: every member scanned)
        order = np.argsort(ms[:n + 1], kind="mergesort")
        for j in range(n + 1):
            ids[j] = order[j]
            keys[j] = ms[order[j]]
        h = dt[r]
        for i in range(n):
            k, c = a + i, cells[a + i]
            s, t, v, own, rd = ms[i], mt[i], mv[i], ml[i], mroad[i]
            accel = 0.0
            lw = law[k]
            if lw == LAW_TRACK:
                accel = speed_tracking(v, params[0, k], params[1, k], params[2, k], h)
            elif lw == LAW_BRAKE:
                accel = brake_accel(v, params[0, k], params[1, k], h)
            elif lw == LAW_IDM:
                found, best, lead, best_m = False, 0.0, 0.0, -1
                if scan:  # `leader_scan`: every member, the first on equal gaps
                    for m in range(n + 1):
                        if m == i or mroad[m] != rd or abs(mt[m] - t) > window_m:
                            continue
                        gap = ms[m] - s - 0.5 * (ml[m] + own)
                        if ms[m] > s and (not found or gap < best):
                            found, best, lead = True, gap, mv[m]
                else:  # `LeaderIndex.leader`: from the first member strictly ahead
                    lo_ = bisect_right(keys, s, n + 1)
                    # (the longest of all the run's members: a lower bound of later gaps on any road)
                    half_longest = 0.5 * (longest + own)
                    for j in range(lo_, n + 1):
                        sj = keys[j]
                        if found and sj - s - half_longest > best + STOP_SLACK_M:
                            break
                        m = ids[j]
                        if m == i or mroad[m] != rd or abs(mt[m] - t) > window_m:
                            continue
                        gap = sj - s - 0.5 * (ml[m] + own)
                        if not found or gap < best or (gap == best and m < best_m):
                            found, best, lead, best_m = True, gap, mv[m], m
                p = params[:, k]
                free = idm_free(v, p[0])
                accel = idm_accel(v, free, best, lead, p[1], p[2], p[3], p[4]) if found else p[1] * free
            # `behaviors.advance`: the station moves by speed / ground scale, less what a lane
            # change takes across the road
            speed = v + accel * h
            speed = speed if speed > 0.0 else 0.0  # max(0.0, speed)
            along = speed * h
            tn = t_new[k]
            if tn != t:
                across = tn - t
                q = along * along - across * across
                along = math.sqrt(0.0 if 0.0 > q else q)  # max(q, 0.0)
            s_new = s + along / flat[4, c]
            flat[0, c], flat[1, c], flat[2, c], flat[3, c] = s_new, tn, speed, accel
            ms[i], mt[i], mv[i] = s_new, tn, speed
            if scan:
                continue
            if not math.isfinite(s_new):
                scan = True
                continue
            # `LeaderIndex.moved`: agent i to its new place in the sorted list
            j = bisect_left(keys, s, n + 1)  # (its old station's place, then on to its own entry)
            while ids[j] != i:
                j += 1
            while j < n and keys[j + 1] <= s_new:
                keys[j], ids[j] = keys[j + 1], ids[j + 1]
                j += 1
            while j > 0 and keys[j - 1] > s_new:
                keys[j], ids[j] = keys[j - 1], ids[j - 1]
                j -= 1
            keys[j], ids[j] = s_new, i
    return left
