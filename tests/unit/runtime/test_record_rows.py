"""The record phase over a batch (`phases._record_rows`): one kernel call writes every live
run's rows of a sample into the batch's block, the egos' from their states block and the
agents' from the pose table; compiled, it gives its Python's bits, and the rows are what the
per-run code writes (`vehicle.ego_record`, `agents.agent_row`, the fields in order)."""

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from addt_dsl import kernel
from addt_dsl.runtime import phases
from addt_dsl.runtime.agent_arrays import ACCEL, S, T
from addt_dsl.runtime.fastroad import POSE_OFFSET, POSE_X, POSE_Y
from addt_dsl.runtime.vehicle import ACCEL as V_ACCEL
from addt_dsl.runtime.vehicle import HEADING, STEER, VX, VY, X, Y, YAW_RATE

value = st.floats(-1e3, 1e3) | st.sampled_from([math.nan, math.inf, -0.0, 1e300])


@settings(max_examples=60, deadline=None)
@given(st.lists(st.integers(0, 4), min_size=1, max_size=6), st.data())
def test_rows_of_a_batch_are_each_fields_in_its_column(counts, data):
    runs = len(counts)
    first = np.array([0, *np.cumsum([1 + n for n in counts])], dtype=np.int64)
    live = np.array(sorted(data.draw(st.sets(st.integers(0, runs - 1), min_size=1))), dtype=np.int64)
    width = len(phases.FIELDS)
    states = np.array(data.draw(st.lists(st.lists(value, min_size=12, max_size=12), min_size=runs, max_size=runs)))
    agents = int(sum(counts))
    pose = np.array(data.draw(st.lists(st.lists(value, min_size=max(agents, 1), max_size=max(agents, 1)),
                                       min_size=9, max_size=9)))
    flat = np.array(data.draw(st.lists(st.lists(value, min_size=2 * max(agents, 1), max_size=2 * max(agents, 1)),
                                       min_size=5, max_size=5)))
    stl = np.array(data.draw(st.lists(st.lists(value, min_size=3, max_size=3), min_size=len(live),
                                      max_size=len(live)))).reshape(-1, 3)
    lo = np.cumsum([0, *counts])[:-1]
    ego_rows = live[::-1].copy()  # (any rows of the states block)
    counts_live = np.array([counts[r] for r in live], dtype=np.int64)
    pose_lo = np.array([lo[r] for r in live], dtype=np.int64)
    cell0 = np.array([agents + lo[r] for r in live], dtype=np.int64)  # (slots other than the pose columns)
    got = []
    for interpreted in (False, True):
        block = np.full((first[-1], width), 7.0)
        args = (block, first, live, states, ego_rows, phases._EGO_COLUMNS, stl, pose, flat, counts_live, pose_lo, cell0)
        if interpreted:
            with kernel.interpreted():
                phases._record_rows(*args)
        else:
            phases._record_rows(*args)
        got.append(kernel.bits(block.ravel()))
        # the rows written out
        want = np.full((first[-1], width), 7.0)
        for j, r in enumerate(live.tolist()):
            c, s = first[r], states[ego_rows[j]]
            want[c, :10] = [s[X], s[Y], s[HEADING], math.hypot(s[VX], s[VY]), s[V_ACCEL], s[YAW_RATE],
                            stl[j, 0], stl[j, 1], stl[j, 2], s[STEER]]
            for i in range(counts[r]):
                k, cell = pose_lo[j] + i, cell0[j] + i
                want[c + 1 + i, :9] = [pose[POSE_X, k], pose[POSE_Y, k], pose[6, k], pose[8, k], flat[ACCEL, cell],
                                       0.0, flat[S, cell], flat[T, cell], pose[POSE_OFFSET, k]]
        assert kernel.bits(block.ravel()) == kernel.bits(want.ravel())
    assert got[0] == got[1]
