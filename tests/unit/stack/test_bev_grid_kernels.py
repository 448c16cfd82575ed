"""`bev_grid`'s overlap kernels against the numpy code they replace (copied verbatim as the
oracle, but for numpy's `arctan2` and `exp`: the C library's on every machine now) and,
compiled, against their own Python."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from addt_dsl.kernel import atan2, exp, interpreted
from addt_dsl.stack import bev_grid


def old_box_penetration(boxes: np.ndarray) -> np.ndarray:
    x, y, h, length, width = (boxes[:, k] for k in range(5))
    c, s = np.cos(h), np.sin(h)
    hl, hw = 0.5 * length, 0.5 * width
    sx = np.array([1.0, 1.0, -1.0, -1.0])
    sy = np.array([1.0, -1.0, -1.0, 1.0])
    cx = x[:, None] + c[:, None] * hl[:, None] * sx - s[:, None] * hw[:, None] * sy  # (N, 4)
    cy = y[:, None] + s[:, None] * hl[:, None] * sx + c[:, None] * hw[:, None] * sy
    axes = np.stack([np.stack([c, s], 1), np.stack([-s, c], 1)], 1)  # (N, 2 axes, 2)
    proj = axes[:, :, 0, None, None] * cx[None, None] + axes[:, :, 1, None, None] * cy[None, None]
    lo, hi = proj.min(axis=3), proj.max(axis=3)  # (k, a, b)
    gap = np.maximum(lo[:, :, None, :] - hi[:, :, :, None], lo[:, :, :, None] - hi[:, :, None, :]).max(axis=1)
    i = np.arange(len(boxes))
    return np.maximum(gap[i[:, None], i[:, None], i[None, :]], gap[i[None, :], i[:, None], i[None, :]])


def old_keep_non_overlapping(boxes: np.ndarray, max_overlap_m: float) -> np.ndarray:
    reach = 0.5 * np.hypot(boxes[:, 3], boxes[:, 4])
    gap = np.hypot(boxes[:, None, 0] - boxes[None, :, 0], boxes[:, None, 1] - boxes[None, :, 1]) \
        - (reach[:, None] + reach[None, :])
    np.fill_diagonal(gap, np.inf)
    if np.isfinite(boxes[:, :5]).all() and not (gap < 0.0).any():
        return np.arange(len(boxes), dtype=np.int64)
    sep = old_box_penetration(boxes)
    keep: list[int] = []
    for i in range(len(boxes)):  # highest score first
        if all(sep[i, j] >= -max_overlap_m for j in keep):
            keep.append(i)
    return np.array(keep, dtype=np.int64)


_NEIGHBOUR_DI = np.array([0, 0, 0, 1, 1, 2, 2, 2])
_NEIGHBOUR_DJ = np.array([0, 1, 2, 0, 2, 0, 1, 2])


def old_decode(heat, reg, threshold, spec=bev_grid.GRID, max_objects=64, max_overlap_m=0.3):
    hx, hy = heat.shape
    i, j = np.nonzero(heat >= threshold)
    if len(i) == 0:
        return np.zeros((0, 7))
    padded = np.full((hx + 2, hy + 2), -np.inf, dtype=heat.dtype)
    padded[1:-1, 1:-1] = heat
    centre = heat[i, j][:, None]
    neighbours = padded[i[:, None] + _NEIGHBOUR_DI, j[:, None] + _NEIGHBOUR_DJ]  # (k, 8)
    is_max = (centre > neighbours[:, :4]).all(axis=1) & (centre >= neighbours[:, 4:]).all(axis=1)
    i, j = i[is_max], j[is_max]
    if len(i) == 0:
        return np.zeros((0, 7))
    conf = heat[i, j]
    order = np.argsort(-conf, kind="stable")[:max_objects]
    i, j, conf = i[order], j[order], conf[order]
    with np.errstate(all="ignore"):
        return _old_boxes(heat, reg, i, j, conf, spec, max_overlap_m)


def _old_boxes(heat, reg, i, j, conf, spec, max_overlap_m):
    c = spec.head_cell_m
    r = reg[:, i, j].astype(np.float64)
    x = spec.x_min + (i + 0.5 + r[0]) * c
    y = spec.y_min + (j + 0.5 + r[1]) * c
    heading = 0.5 * atan2.over(r[4], r[5])
    cls = r[6:].argmax(axis=0).astype(np.float64) if len(r) > 6 else np.full(len(i), -1.0)
    boxes = np.stack([x, y, heading, exp.over(r[2]), exp.over(r[3]), conf.astype(np.float64), cls], axis=1)
    if max_overlap_m is not None and len(boxes) > 1:
        boxes = boxes[old_keep_non_overlapping(boxes, max_overlap_m)]
    return boxes


odd = st.sampled_from([math.nan, math.inf, -math.inf, 0.0, -0.0])


@st.composite
def box_sets(draw):
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    n = draw(st.integers(2, 12))
    spread = draw(st.sampled_from([3.0, 10.0, 40.0]))
    boxes = np.column_stack([rng.uniform(-spread, spread, n), rng.uniform(-spread, spread, n),
                             rng.uniform(-3.2, 3.2, n), rng.uniform(0.3, 14, n), rng.uniform(0.3, 3, n),
                             np.sort(rng.uniform(0, 1, n))[::-1], rng.integers(0, 4, n)])
    for _ in range(draw(st.integers(0, 2))):
        boxes[draw(st.integers(0, n - 1)), draw(st.integers(0, 4))] = draw(odd)
    if draw(st.booleans()):
        boxes[1, :5] = boxes[0, :5]  # the same box twice
    return boxes


def same(a, b) -> bool:  # equal values (a zero's sign aside), NaN where NaN
    return a.shape == b.shape and bool(np.all((a == b) | (np.isnan(a) & np.isnan(b))))


@settings(max_examples=200, deadline=None)
@given(box_sets(), st.sampled_from([0.0, 0.3, 1.0]))
def test_overlap_kernels_give_the_numpy_codes_answers(boxes, max_overlap_m):
    with np.errstate(all="ignore"):
        want_sep = old_box_penetration(boxes)
        want_keep = old_keep_non_overlapping(boxes, max_overlap_m)
        got_sep = bev_grid.box_penetration(boxes)
        got_keep = bev_grid._keep_non_overlapping(boxes, max_overlap_m)
        with interpreted():
            py_sep = bev_grid.box_penetration(boxes)
            py_keep = bev_grid._keep_non_overlapping(boxes, max_overlap_m)
    assert same(got_sep, want_sep) and same(py_sep, got_sep)
    assert got_sep.view(np.int64)[~np.isnan(got_sep)].tolist() == py_sep.view(np.int64)[~np.isnan(py_sep)].tolist()
    assert got_keep.tolist() == want_keep.tolist() == py_keep.tolist()


def test_two_trucks_end_to_end_keep_the_stronger():
    boxes = np.array([[0.0, 0.0, 0.0, 12.0, 2.5, 0.9, 1.0], [4.8, 0.0, 0.0, 12.0, 2.5, 0.6, 1.0],
                      [0.0, 9.6, 0.0, 12.0, 2.5, 0.5, 1.0]])
    assert bev_grid._keep_non_overlapping(boxes, 0.3).tolist() == [0, 2]
    # 7.2 m of overlap along (12 m long, 4.8 m apart), 2.5 across (same line): the shallower
    assert bev_grid.box_penetration(boxes)[0, 1] == -2.5


@st.composite
def head_maps(draw):
    """Small score maps at the grid's size: a few levels (plateaus and ties), NaN/inf at
    times; box rows; a threshold on a level or just off it in float32."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    shape = bev_grid.GRID.head_shape
    levels = np.array(draw(st.lists(st.floats(-3, 3, width=32), min_size=1, max_size=6)), dtype=np.float32)
    heat = levels[rng.integers(0, len(levels), shape)]
    for _ in range(draw(st.integers(0, 3))):
        heat[rng.integers(0, shape[0]), rng.integers(0, shape[1])] = draw(odd)
    reg = rng.normal(0, 1, (6 + draw(st.sampled_from([0, 4])), *shape)).astype(np.float32)
    base = float(draw(st.sampled_from(list(levels))))
    threshold = draw(st.sampled_from([base, base + 1e-12, base - 1e-12, float(np.nextafter(np.float32(base), 9)),
                                      -math.inf]))
    return heat, reg, threshold


@settings(max_examples=150, deadline=None)
@given(head_maps(), st.sampled_from([64, 3, 1, 0]), st.sampled_from([0.3, None]))
def test_decode_gives_the_numpy_codes_boxes(maps, max_objects, max_overlap_m):
    heat, reg, threshold = maps
    with np.errstate(all="ignore"):
        want = old_decode(heat, reg, threshold, max_objects=max_objects, max_overlap_m=max_overlap_m)
        got = bev_grid.decode(heat, reg, threshold, max_objects=max_objects, max_overlap_m=max_overlap_m)
        with interpreted():
            py = bev_grid.decode(heat, reg, threshold, max_objects=max_objects, max_overlap_m=max_overlap_m)
    assert got.shape == want.shape == py.shape
    for a in (got, py):
        assert a.view(np.int64)[~np.isnan(a)].tolist() == want.view(np.int64)[~np.isnan(want)].tolist()
        assert np.isnan(a).tolist() == np.isnan(want).tolist()


def test_decode_compares_in_the_maps_dtype():
    """numpy compares a float32 map with the threshold in float32: a threshold a hair above
    a float32 value still takes that value's peak."""
    heat = np.zeros(bev_grid.GRID.head_shape, dtype=np.float32)
    heat[10, 10] = np.float32(0.1)
    reg = np.zeros((6, *bev_grid.GRID.head_shape), dtype=np.float32)
    threshold = float(np.float32(0.1)) + 1e-12
    assert len(bev_grid.decode(heat, reg, threshold)) == len(old_decode(heat, reg, threshold)) == 1
