"""The clearances kernel (`collision._clearances`) and the separation it calls
(`world.separation`): compiled, each gives its Python source's bits; `separation` is the
plain `max` formula it replaced; hand-checked gaps and contacts; non-finite poses as every
pair; more contacts than the first buffer holds. (`kernel.hypot`: tests/unit/core/test_kernel.py.)"""

from __future__ import annotations

import contextlib
import math
from types import SimpleNamespace

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from addt_dsl.kernel import bits, interpreted
from addt_dsl.runtime import collision as C
from addt_dsl.runtime.world import box_separation, separation


special = st.sampled_from([0.0, -0.0, 5e-324, 1e-310, 2.2250738585072014e-308, 1e-160, 1e160, 1.7976931348623157e308,
                           math.inf, -math.inf, math.nan, 3.0, 4.0, -4.0])
anyfloat = st.floats(allow_nan=True, allow_infinity=True) | special


# ---------------------------------------------------------------- separation

def max_separation(dx, dy, ca, sa, cb, sb, la, wa, lb, wb):
    """`world.separation` before it was a kernel (verbatim, Python's `max`)."""
    cos_d = abs(ca * cb + sa * sb)
    sin_d = abs(sa * cb - ca * sb)
    la, wa, lb, wb = 0.5 * la, 0.5 * wa, 0.5 * lb, 0.5 * wb
    return max(
        abs(dx * ca + dy * sa) - (la + lb * cos_d + wb * sin_d),
        abs(dy * ca - dx * sa) - (wa + lb * sin_d + wb * cos_d),
        abs(dx * cb + dy * sb) - (lb + la * cos_d + wa * sin_d),
        abs(dy * cb - dx * sb) - (wb + la * sin_d + wa * cos_d),
    )


@settings(max_examples=300, deadline=None)
@given(st.lists(anyfloat | st.floats(-50.0, 50.0), min_size=10, max_size=10))
def test_separation_is_the_max_formula(args):
    want = bits([max_separation(*args)])  # NaN first kept, a later NaN passed over: max's order
    assert bits([separation(*args)]) == want
    assert bits([separation.py_func(*args)]) == want


def test_separation_by_hand():
    # Axis-aligned 4 x 2 boxes, centres 10 m apart along x: 10 - 2 - 2 = 6 m.
    assert box_separation((0.0, 0.0, 0.0, 4.0, 2.0), (10.0, 0.0, 0.0, 4.0, 2.0)) == 6.0
    # Side by side 3 m apart in y (widths 2): 1 m; overlapping by 1 m in x: -1 m.
    assert box_separation((0.0, 0.0, 0.0, 4.0, 2.0), (0.0, 3.0, 0.0, 4.0, 2.0)) == 1.0
    assert box_separation((0.0, 0.0, 0.0, 4.0, 2.0), (3.0, 0.0, 0.0, 4.0, 2.0)) == -1.0
    # Turned a quarter: b's 4 m length along y, its half-width 1 m along x: 10 - 2 - 1 = 7 m.
    assert math.isclose(box_separation((0.0, 0.0, 0.0, 4.0, 2.0), (10.0, 0.0, math.pi / 2, 4.0, 2.0)), 7.0)
    assert box_separation((0, 0, 0, 4, 2), (10, 0, 0, 4, 2)) == 6.0  # ints as floats


# ---------------------------------------------------------------- the clearances kernel

def rows_of(boxes):
    rows = np.full((len(boxes), 11), np.nan)
    rows[:, :3] = [b[:3] for b in boxes] if boxes else np.empty((0, 3))
    return rows, np.array([b[3:] for b in boxes], dtype=float).reshape(-1, 2)


coordinate = st.one_of(st.integers(0, 12).map(lambda i: 6.0 * i), st.floats(-40.0, 120.0),
                       st.floats(1e9, 1e9 + 30.0),  # far out: ulps of metres, slacks of kilometres
                       st.sampled_from([math.nan, math.inf, -math.inf, 1e200, -0.0]))
offset = st.sampled_from([-5.25, -1.75, 1.75, 0.0, -0.0]) | st.floats(-8.0, 4.0) | st.just(math.nan)
heading = st.floats(-0.4, 0.4) | st.sampled_from([0.0, -0.0, math.pi / 2, math.nan])
size = st.sampled_from([(4.6, 1.9), (12.0, 2.5), (0.6, 0.6), (0.0, 0.0)])
box = st.tuples(coordinate, offset, heading, size).map(lambda b: (*b[:3], *b[3]))


@settings(max_examples=150, deadline=None)
@given(st.lists(st.lists(box, min_size=1, max_size=12), min_size=1, max_size=5), st.randoms(use_true_random=False))
def test_compiled_gives_its_python_bits(runs, rnd):
    """Batches of 1..5 runs of 1..12 actors (NaN, inf, huge and -0.0 poses included), all
    of them or some (the live runs of a batch whose others ended)."""
    boxes = [b for run in runs for b in run]
    first = np.array([0, *np.cumsum([len(r) for r in runs])], dtype=np.int64)
    live = np.array(sorted(rnd.sample(range(len(runs)), rnd.randint(1, len(runs)))), dtype=np.int64)
    results = []
    for python in (False, True):  # compiled; its Python, callees (`_pair`, hypot, separation) included
        rows, sizes = rows_of(boxes)
        touch = np.full((len(boxes) + 8, 3), -1, dtype=np.int64)
        with np.errstate(all="ignore"), interpreted() if python else contextlib.nullcontext():
            found = C._clearances(first, live, rows, sizes, touch)
        results.append((found, bits(rows.ravel()), touch.tolist()))
    assert results[0] == results[1]


@settings(max_examples=80, deadline=None)
@given(st.lists(st.lists(box, min_size=1, max_size=10), min_size=2, max_size=5), st.randoms(use_true_random=False))
def test_the_live_runs_of_a_batch_rows_are_each_run_alone(runs, rnd):
    """`clearances_rows` on the rows of a whole batch, some runs live: each live run's
    clearances and events are those it gets alone (`reference`), the other runs' rows
    untouched."""
    boxes = [b for run in runs for b in run]
    first = np.array([0, *np.cumsum([len(r) for r in runs])], dtype=np.int64)
    live = sorted(rnd.sample(range(len(runs)), rnd.randint(1, len(runs))))
    rows, sizes = rows_of(boxes)
    before = rows.copy()
    items = [([f"a{i}" for i in range(len(runs[k]))], SimpleNamespace(contacts=set(), events=[]), 0.5)
             for k in live]
    with np.errstate(all="ignore"):
        collided = C.clearances_rows(rows, first, np.array(live, dtype=np.int64), sizes, items)
        for k, (names, run, _), hit in zip(live, items, collided):
            clear, touching = reference(runs[k])
            assert bits(rows[first[k]:first[k + 1], -1]) == bits(clear)
            assert [tuple(e.detail["actors"]) for e in run.events] == [(names[a], names[b]) for a, b in touching]
            assert hit is False  # (no actor named ego)
    for k in set(range(len(runs))) - set(live):
        assert bits(rows[first[k]:first[k + 1]].ravel()) == bits(before[first[k]:first[k + 1]].ravel())


def reference(boxes):
    """Every pair in order: the clearance loop before the kernel (math.hypot, `max`)."""
    reach = [0.5 * math.hypot(b[3], b[4]) for b in boxes]
    clear, touching = [math.inf] * len(boxes), []
    for a in range(len(boxes)):
        for b in range(a + 1, len(boxes)):
            (xa, ya, ha, la, wa), (xb, yb, hb, lb, wb) = boxes[a], boxes[b]
            dist = math.hypot(xa - xb, ya - yb)
            r = reach[a] + reach[b]
            sep = dist - r if dist > r + 5.0 else max_separation(
                xb - xa, yb - ya, math.cos(ha), math.sin(ha), math.cos(hb), math.sin(hb), la, wa, lb, wb)
            if sep < clear[a]:
                clear[a] = sep
            if sep < clear[b]:
                clear[b] = sep
            if sep <= 0.0:
                touching.append((a, b))
    return [c if math.isfinite(c) else 1e3 for c in clear], touching


@settings(max_examples=150, deadline=None)
@given(st.lists(box, min_size=1, max_size=16))
def test_non_finite_poses_as_every_pair(boxes):
    rows, sizes = rows_of(boxes)
    names = [f"a{i}" for i in range(len(boxes))]
    run = SimpleNamespace(contacts=set(), events=[])
    with np.errstate(all="ignore"):
        C.clearances(rows, names, sizes, run, 0.0)
        clear, touching = reference(boxes)
    assert bits(rows[:, -1]) == bits(clear)
    assert [tuple(e.detail["actors"]) for e in run.events] == [(names[a], names[b]) for a, b in touching]


def test_gaps_and_contacts_by_hand():
    # ego and a, 4 x 2 m, 9 m apart in x (5 m: within reach + 5 m, the boxes' gap); b 3 m
    # beside a (1 m); c overlaps b by 1 m (-1 m); d alone ~500 m away (over reach + 5 m:
    # the centre distance less the half-diagonals, to c).
    boxes = [(0.0, 0.0, 0.0, 4.0, 2.0), (9.0, 0.0, 0.0, 4.0, 2.0), (9.0, 3.0, 0.0, 4.0, 2.0),
             (12.0, 3.0, 0.0, 4.0, 2.0), (509.0, 0.0, 0.0, 4.0, 2.0)]
    names = ["ego", "a", "b", "c", "d"]
    rows, sizes = rows_of(boxes)
    run = SimpleNamespace(contacts={("ego", "x")}, events=[])
    hit = C.clearances(rows, names, sizes, run, 1.5)
    d_gap = math.hypot(497.0, 3.0) - 2 * 0.5 * math.hypot(4.0, 2.0)  # d to c
    assert rows[:, -1].tolist() == [5.0, 1.0, -1.0, -1.0, d_gap]
    assert [(e.time_s, e.kind, e.detail["actors"]) for e in run.events] == [(1.5, "collision", ["b", "c"])]
    assert run.contacts == {("b", "c")} and hit is False
    C.clearances(rows, names, sizes, run, 1.6)  # still touching: no new event
    assert len(run.events) == 1
    rows[0, :2] = (9.0, 3.0)  # the ego onto b and c: both events, in all-pairs order
    assert C.clearances(rows, names, sizes, run, 1.7) is True
    assert [e.detail["actors"] for e in run.events[1:]] == [["ego", "b"], ["ego", "c"]]
    lone = np.zeros((1, 11))
    C.clearances(lone, ["ego"], np.array([[4.0, 2.0]]), SimpleNamespace(contacts=set(), events=[]), 0.0)
    assert lone[0, -1] == 1e3  # nobody else: no finite separation


def test_more_contacts_than_the_first_buffer():
    boxes = [(0.1 * i, 0.0, 0.0, 4.6, 1.9) for i in range(12)]  # 66 touching pairs, room for 20 at first
    items, expected = [], []
    for shift in (0.0, 100.0):  # two runs: (run, i, j) keeps them apart
        moved = [(x + shift, *rest) for x, *rest in boxes]
        rows, sizes = rows_of(moved)
        items.append((rows, [f"a{i}" for i in range(12)], sizes, SimpleNamespace(contacts=set(), events=[]), 0.0))
        expected.append(reference(moved))
    C.clearances_batch(items)
    for (rows, names, _, run, _), (clear, touching) in zip(items, expected):
        assert len(touching) == 66
        assert [tuple(e.detail["actors"]) for e in run.events] == [(names[a], names[b]) for a, b in touching]
        assert bits(rows[:, -1]) == bits(clear)
