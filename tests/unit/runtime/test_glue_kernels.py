"""The kernels that replaced the loop's numpy glue: `agents._agent_rows` (a step's agent
rows of the record) and `world._put_poses` (the bodies' poses into the box table). Each
compiled gives its Python's bits, and both give what the numpy code they replaced gave
(copied verbatim below as the oracle), over random values (NaN, inf, -0.0 among them) and
batches of 1..N runs."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from addt_dsl.kernel import bits, interpreted
from addt_dsl.runtime import agents as A
from addt_dsl.runtime import world as W
from addt_dsl.runtime.agent_arrays import ACCEL, FIELDS, SPEED, S, T
from addt_dsl.runtime.fastroad import POSE_OFFSET, POSE_X, POSE_Y, POSE_Z

values = st.floats(allow_nan=True, allow_infinity=True, allow_subnormal=True) | st.sampled_from([0.0, -0.0])


def _table(data, rows: int, cols: int) -> np.ndarray:
    return np.array(data.draw(st.lists(values, min_size=rows * cols, max_size=rows * cols)),
                    dtype=float).reshape(rows, cols)


def _old_record(row, x, y, heading, v, values_block, run_row, n, lane_offset):
    """`Fleet.record` before `_agent_rows` (posed as arrays), verbatim but for its inputs."""
    zero = np.zeros(n)
    s, t, _, accel = values_block[:ACCEL + 1, run_row, :n]  # (as posed: nothing moved since)
    row[:, :9].T[:] = (x, y, heading, v, accel, zero, s, t, lane_offset)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.integers(1, 6), min_size=1, max_size=4), st.data())
def test_agent_rows_are_the_old_record_and_their_python(counts, data):
    runs, width = len(counts), max(counts) + 1  # (a slot of padding in each run)
    block = _table(data, len(FIELDS), runs * width).reshape(len(FIELDS), runs, width)
    flat = block.reshape(len(FIELDS), runs * width)
    lo = np.cumsum([0, *counts]).tolist()
    pose = _table(data, A._POSE_ROWS, lo[-1])
    pose[A._SPEED] = np.concatenate([block[SPEED, r, :n] for r, n in enumerate(counts)])  # (as `_body_poses` has it)
    k = data.draw(st.integers(0, 2))
    for r, n in enumerate(counts):
        cells = np.arange(r * width, r * width + n, dtype=np.intp)
        got, python, want = (np.full((3, n + 1, 11), 7.0) for _ in range(3))
        A._agent_rows(got, k, pose, lo[r], flat, cells)
        with interpreted():
            A._agent_rows(python, k, pose, lo[r], flat, cells)
        p = pose[:, lo[r]:lo[r + 1]]
        _old_record(want[k, 1:], p[POSE_X], p[POSE_Y], p[A._HEADING], p[A._SPEED], block, r, n, p[POSE_OFFSET])
        assert bits(got) == bits(python) == bits(want)
        assert got.view(np.int64).tolist() == want.view(np.int64).tolist()  # (copies: NaN payloads too)


def _old_set_poses(box, unsynced, slots, x, y, z, heading, pitch):
    """`PhysicsWorld.set_poses` before `_put_poses`, verbatim but for its inputs."""
    if isinstance(slots, slice):
        box[slots].T[:] = (x, y, z, heading, pitch)
    else:
        box[slots] = np.stack([x, y, z, heading, pitch], axis=1)
    unsynced[slots] = True


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 8), st.integers(0, 3), st.booleans(), st.data())
def test_put_poses_is_the_old_set_poses_and_its_python(n, lo, contiguous, data):
    boxes = n + 3
    slots = (np.arange(1, n + 1) if contiguous else
             np.array(data.draw(st.permutations(range(boxes)))[:n])).astype(np.intp)
    table = _table(data, A._POSE_ROWS, lo + n + 2)
    before = _table(data, boxes, 5)
    marks = np.array(data.draw(st.lists(st.booleans(), min_size=boxes, max_size=boxes)))
    got, python, want = before.copy(), before.copy(), before.copy()
    got_u, python_u, want_u = marks.copy(), marks.copy(), marks.copy()
    W._put_poses(got, got_u, slots, table, lo, A._BODY_COLUMNS)
    with interpreted():
        W._put_poses(python, python_u, slots, table, lo, A._BODY_COLUMNS)
    p = table[:, lo:lo + n]
    old_slots = slice(1, n + 1) if contiguous else slots
    _old_set_poses(want, want_u, old_slots, p[POSE_X], p[POSE_Y], p[POSE_Z], p[A._HEADING], p[A._PITCH])
    assert got.view(np.int64).tolist() == python.view(np.int64).tolist() == want.view(np.int64).tolist()
    assert got_u.tolist() == python_u.tolist() == want_u.tolist()


def test_hand_checked_row_and_pose():
    pose = np.arange(A._POSE_ROWS * 2, dtype=float).reshape(A._POSE_ROWS, 2)  # pose[r, j] = 2 r + j
    flat = np.arange(len(FIELDS) * 3, dtype=float).reshape(len(FIELDS), 3) + 100.0
    block = np.full((1, 2, 11), -1.0)
    A._agent_rows(block, 0, pose, 1, flat, np.array([2], dtype=np.intp))
    assert block[0, 0].tolist() == [-1.0] * 11  # the ego's row untouched
    assert block[0, 1].tolist() == [2 * POSE_X + 1, 2 * POSE_Y + 1, 2 * A._HEADING + 1, 2 * A._SPEED + 1,
                                    flat[ACCEL, 2], 0.0, flat[S, 2], flat[T, 2], 2 * POSE_OFFSET + 1, -1.0, -1.0]
    box, unsynced = np.zeros((3, 5)), np.zeros(3, dtype=bool)
    W._put_poses(box, unsynced, np.array([2], dtype=np.intp), pose, 0, A._BODY_COLUMNS)
    assert box.tolist() == [[0.0] * 5, [0.0] * 5, [2.0 * c for c in A._BODY_COLUMNS.tolist()]]
    assert unsynced.tolist() == [False, False, True]


@settings(max_examples=60, deadline=None)
@given(st.data())
def test_poses_kept_aside_reach_the_table_in_call_order(data):
    """`set_pose` and `set_poses` calls in any order and number (the same slots' array again
    and again, other slots' arrays, a body posed each way in turn), the table read at any
    point: it holds what writing each call through at once would (the last pose of each box,
    every posed box marked for pybullet)."""
    world = W.PhysicsWorld()
    names = [f"b{i}" for i in range(5)]
    for name in names:
        world.add_box(name, 4.0, 2.0, 1.5)
    slot_sets = [np.array(world.box_slots(names[i:j]), dtype=np.intp) for i, j in ((0, 2), (1, 4), (3, 5), (0, 5))]
    want, want_u = world.box_poses().copy(), np.zeros(len(names), dtype=bool)
    for _ in range(data.draw(st.integers(1, 14))):
        op = data.draw(st.sampled_from(["pose", "poses", "poses", "read"]))
        if op == "pose":
            k = data.draw(st.integers(0, len(names) - 1))
            row = tuple(data.draw(st.floats(-50.0, 50.0)) for _ in range(5))
            world.set_pose(names[k], *row)
            want[k], want_u[k] = row, True
        elif op == "poses":
            slots = slot_sets[data.draw(st.integers(0, len(slot_sets) - 1))]
            lo = data.draw(st.integers(0, 2))
            table = np.array(data.draw(st.lists(st.floats(-50.0, 50.0), min_size=A._POSE_ROWS * (lo + 5),
                                                max_size=A._POSE_ROWS * (lo + 5)))).reshape(A._POSE_ROWS, lo + 5)
            world.set_poses(slots, table, lo, A._BODY_COLUMNS)
            for i, slot in enumerate(slots.tolist()):
                want[slot], want_u[slot] = table[A._BODY_COLUMNS, lo + i], True
        else:
            assert world.box_poses().tolist() == want.tolist()
    assert world.box_poses().tolist() == want.tolist()
    assert world._unsynced.tolist() == want_u.tolist()
