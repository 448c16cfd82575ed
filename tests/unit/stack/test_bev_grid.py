"""BEV grid building and CenterNet target encoding / decoding (numpy only)."""

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from addt_dsl.stack.bev_grid import (BOX_CHANNELS, CHANNELS, CLASSES, GRID, build_grid, decode, encode_targets,
                                     sensor_points_to_vehicle)
from addt_dsl.runtime.sensors import Extrinsics, sensor_to_vehicle


def test_single_point_lands_in_its_cell_with_subcell_features():
    # x = 10.1 m: (10.1 + 60.8) / 0.8 = 88.625 -> cell 88, offset 0.125 cells from the centre.
    # y = -3.0 m: (-3.0 + 25.6) / 0.8 = 28.25 -> cell 28, offset -0.25.
    grid = build_grid(np.array([[10.1, -3.0, 1.2]]), (1.0, 0.0))
    assert grid.shape == (CHANNELS, GRID.nx, GRID.ny)
    occupied = np.argwhere(grid[0] > 0)
    assert occupied.tolist() == [[88, 28]]
    cell = grid[:, 88, 28]
    assert cell[0] == 0.25  # one point of the four that saturate occupancy
    assert math.isclose(cell[1], 0.125, abs_tol=1e-5)
    assert math.isclose(cell[2], -0.25, abs_tol=1e-5)
    assert math.isclose(cell[3], 0.6, abs_tol=1e-6)  # max z / 2
    d = np.array([10.1 - 1.0, -3.0])
    r = np.linalg.norm(d)
    assert np.allclose(cell[4:6], d / r, atol=1e-6)
    assert math.isclose(cell[6], r / 60.0, rel_tol=1e-6)  # range from the sensor [m] / 60
    assert math.isclose(cell[7], 1.0 / 5.0, rel_tol=1e-6)  # log2(1 + 1) / 5
    assert np.count_nonzero(grid) == CHANNELS  # nothing else set


def test_range_and_count_channels_say_how_far_and_how_many():
    """Ten returns in one cell: occupancy saturates at 4, the count channel does not, and
    the range channel is their mean horizontal distance from the sensor (what tells a
    height's beam and a count's width: a cyclist end on from a pedestrian)."""
    sensor = (1.0, 0.5)
    pts = np.column_stack([np.linspace(20.05, 20.7, 10), np.full(10, 3.3), np.linspace(0.5, 1.6, 10)])
    grid = build_grid(pts, sensor)
    (i, j), = np.argwhere(grid[0] > 0).tolist()
    cell = grid[:, i, j]
    assert cell[0] == 1.0
    assert math.isclose(cell[7], math.log2(11.0) / 5.0, rel_tol=1e-6)
    r = np.hypot(pts[:, 0] - sensor[0], pts[:, 1] - sensor[1]).mean()
    assert math.isclose(cell[6], r / 60.0, rel_tol=1e-6)
    # The same returns 20 m further on: a longer range, the same count.
    far = build_grid(pts + [20.0, 0.0, 0.0], sensor)
    (i2, j2), = np.argwhere(far[0] > 0).tolist()
    assert far[7, i2, j2] == cell[7] and far[6, i2, j2] > cell[6] + 19.0 / 60.0


def test_points_outside_the_grid_are_dropped_and_empty_input_is_empty():
    pts = np.array([[100.0, 0.0, 1.0], [0.0, -40.0, 1.0], [-61.0, 0.0, 1.0]])
    assert not build_grid(pts, (0.0, 0.0)).any()
    assert not build_grid(np.zeros((0, 3)), (0.0, 0.0)).any()


def test_ground_returns_are_dropped():
    # A multi-channel lidar's lower beams reach the road: those points are not objects.
    road = np.array([[12.0, 1.0, 0.0], [20.0, -2.0, 0.3], [25.0, 0.0, -0.2]])
    assert not build_grid(road, (1.0, 0.0)).any()
    grid = build_grid(np.vstack([road, [[12.0, 1.0, 0.31]]]), (1.0, 0.0))
    assert np.count_nonzero(grid[0]) == 1 and grid[0].max() == 0.25


def test_out_buffer_is_cleared_between_frames():
    buf = np.zeros(GRID.shape, dtype=np.float32)
    build_grid(np.array([[5.0, 5.0, 1.0]]), (0.0, 0.0), out=buf)
    build_grid(np.array([[-5.0, -5.0, 1.0]]), (0.0, 0.0), out=buf)
    assert np.array_equal(buf, build_grid(np.array([[-5.0, -5.0, 1.0]]), (0.0, 0.0)))


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.floats(-70, 70), st.floats(-30, 30), st.floats(0, 4)), min_size=1, max_size=60))
def test_occupancy_matches_the_cells_of_in_range_points(points):
    pts = np.array(points, dtype=np.float64)
    grid = build_grid(pts, (1.0, 0.0))
    ix = np.floor((pts[:, 0] - GRID.x_min) / GRID.cell_m).astype(int)
    iy = np.floor((pts[:, 1] - GRID.y_min) / GRID.cell_m).astype(int)
    ok = (ix >= 0) & (ix < GRID.nx) & (iy >= 0) & (iy < GRID.ny) & (pts[:, 2] > GRID.ground_m)
    expected = {(int(a), int(b)) for a, b in zip(ix[ok], iy[ok])}
    assert {tuple(c) for c in np.argwhere(grid[0] > 0).tolist()} == expected
    # Mean offsets stay inside the cell.
    assert np.all(np.abs(grid[1:3]) <= 0.5 + 1e-6)


def test_sensor_to_vehicle_matches_the_runtime_transform():
    ext = Extrinsics(1.2, -0.3, 1.1, 0.01, -0.02, 0.3)
    pts = np.random.default_rng(0).normal(size=(20, 3)) * 10
    assert np.allclose(sensor_points_to_vehicle(pts, ext), sensor_to_vehicle(pts, ext))


boxes_strategy = st.lists(
    st.tuples(st.floats(-55, 55), st.floats(-22, 22), st.floats(-math.pi + 0.01, math.pi - 0.01),
              st.floats(3.5, 14.0), st.floats(1.5, 2.7)),
    min_size=1, max_size=12)


@settings(max_examples=40, deadline=None)
@given(boxes_strategy)
def test_encode_then_decode_recovers_well_separated_boxes(boxes):
    boxes = np.array(boxes)
    # Keep boxes whose centres lie more than two head cells apart along x or y, so that their
    # rounded cells are outside each other's 3×3 peak window. (A Euclidean 2.5 cells was not
    # enough: centres 1.875 cells apart on both axes can round to diagonal neighbours.)
    keep = []
    for b in boxes:
        if all(max(abs(b[0] - k[0]), abs(b[1] - k[1])) > 2.0 * GRID.head_cell_m for k in keep):
            keep.append(b)
    boxes = np.array(keep)
    heat, reg, mask = encode_targets(boxes)
    assert mask.sum() == len(boxes)
    found = decode(heat, reg, threshold=0.999, max_overlap_m=None)  # random boxes may overlap
    assert len(found) == len(boxes)
    for b in boxes:
        k = int(np.argmin(np.hypot(found[:, 0] - b[0], found[:, 1] - b[1])))
        x, y, h, length, width, conf, cls = found[k]
        assert cls == -1  # a regression without class logits
        assert math.hypot(x - b[0], y - b[1]) < 1e-4
        assert abs(math.remainder(h - b[2], math.pi)) < 1e-5  # the box axis: front and back alike
        assert -math.pi / 2 - 1e-9 <= h <= math.pi / 2 + 1e-9
        assert math.isclose(length, b[3], rel_tol=1e-5) and math.isclose(width, b[4], rel_tol=1e-5)
        assert conf == 1.0


def test_decode_suppresses_non_peaks_and_respects_threshold():
    heat = np.zeros(GRID.head_shape, dtype=np.float32)
    reg = np.zeros((6, *GRID.head_shape), dtype=np.float32)
    reg[5] = 1.0  # cos = 1: heading 0
    heat[10, 10], heat[10, 11], heat[30, 5] = 0.9, 0.8, 0.4  # (10, 11) is not a peak
    found = decode(heat, reg, threshold=0.5)
    assert len(found) == 1 and math.isclose(found[0, 5], 0.9, rel_tol=1e-6)
    assert len(decode(heat, reg, threshold=0.3)) == 2
    # A plateau yields one peak.
    heat[:] = 0
    heat[20, 8] = heat[20, 9] = 0.7
    assert len(decode(heat, reg, threshold=0.5)) == 1


def test_class_targets_and_the_class_output():
    boxes = np.array([[10.0, 2.0, 0.0, 0.5, 0.5], [-20.0, -3.0, 0.3, 1.8, 0.6]])
    heat, reg, mask = encode_targets(boxes, classes=np.array([CLASSES.index("pedestrian"),
                                                               CLASSES.index("cyclist")]))
    assert reg.shape[0] == BOX_CHANNELS + 1
    centres = np.argwhere(mask > 0)
    assert sorted(reg[BOX_CHANNELS][tuple(centres.T)].tolist()) == [2.0, 3.0]
    # The network's class output is one logit per class after the box rows: the largest wins.
    logits = np.zeros((len(CLASSES), *GRID.head_shape), dtype=np.float32)
    for (i, j), cls in zip(centres, reg[BOX_CHANNELS][tuple(centres.T)].astype(int)):
        logits[cls, i, j] = 3.0
    found = decode(heat, np.concatenate([reg[:BOX_CHANNELS], logits]), threshold=0.999)
    assert sorted(CLASSES[int(c)] for c in found[:, 6]) == ["cyclist", "pedestrian"]


def test_decode_works_on_logits_at_the_border():
    heat = np.full(GRID.head_shape, -9.0, dtype=np.float32)
    reg = np.zeros((6, *GRID.head_shape), dtype=np.float32)
    heat[0, 0] = -1.2  # logit of 0.23, in the corner
    assert len(decode(heat, reg, threshold=-1.4)) == 1


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.floats(-20, 20), st.floats(-20, 20), st.floats(-3.2, 3.2),
                          st.floats(0.5, 14), st.floats(0.5, 3)), min_size=2, max_size=8))
def test_box_penetration_matches_the_runtime_separating_axis_test(boxes):
    from addt_dsl.runtime.world import box_separation
    from addt_dsl.stack.bev_grid import box_penetration

    arr = np.array(boxes)
    sep = box_penetration(arr)
    for i in range(len(arr)):
        for j in range(len(arr)):
            if i != j:
                assert math.isclose(sep[i, j], box_separation(tuple(arr[i]), tuple(arr[j])), abs_tol=1e-9)


def test_decode_drops_a_box_overlapping_a_stronger_one():
    heat = np.zeros(GRID.head_shape, dtype=np.float32)
    reg = np.zeros((6, *GRID.head_shape), dtype=np.float32)
    reg[5] = 1.0  # heading 0
    reg[2], reg[3] = math.log(12.0), math.log(2.5)  # truck-sized everywhere
    heat[40, 16], heat[43, 16] = 0.9, 0.6  # 4.8 m apart along x: two 12 m boxes overlap
    heat[40, 10] = 0.5  # 9.6 m to the side: a separate object
    kept = decode(heat, reg, threshold=0.3)
    assert sorted(kept[:, 5].round(2).tolist()) == [0.5, 0.9]
    assert len(decode(heat, reg, threshold=0.3, max_overlap_m=None)) == 3


def _reference_grid(points, sensor_xy):
    """Point-by-point definition of the features (slow, obviously right)."""
    grid = np.zeros(GRID.shape, dtype=np.float64)
    cells: dict = {}
    for x, y, z in points:
        i = math.floor((x - GRID.x_min) / GRID.cell_m)
        j = math.floor((y - GRID.y_min) / GRID.cell_m)
        if 0 <= i < GRID.nx and 0 <= j < GRID.ny and z > GRID.ground_m:
            cells.setdefault((i, j), []).append((x, y, z))
    for (i, j), pts in cells.items():
        n = len(pts)
        grid[0, i, j] = min(n, 4) / 4
        grid[1, i, j] = sum((x - GRID.x_min) / GRID.cell_m - i - 0.5 for x, _, _ in pts) / n
        grid[2, i, j] = sum((y - GRID.y_min) / GRID.cell_m - j - 0.5 for _, y, _ in pts) / n
        grid[3, i, j] = max(z for _, _, z in pts) / 2
        dirs = [((x - sensor_xy[0]), (y - sensor_xy[1])) for x, y, _ in pts]
        grid[4, i, j] = sum(dx / max(math.hypot(dx, dy), 1e-6) for dx, dy in dirs) / n
        grid[5, i, j] = sum(dy / max(math.hypot(dx, dy), 1e-6) for dx, dy in dirs) / n
        grid[6, i, j] = sum(max(math.hypot(dx, dy), 1e-6) for dx, dy in dirs) / n / 60.0
        grid[7, i, j] = math.log2(1 + n) / 5
    return grid


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.floats(-62, 62), st.floats(-27, 27), st.floats(0, 4)), max_size=80),
       st.integers(0, 3))
def test_grid_matches_the_point_by_point_definition(points, duplicate_every):
    # Clustered points (several per cell) are the interesting case: repeat some.
    pts = list(points)
    if duplicate_every:
        pts += [(x + 0.01, y - 0.01, z + 0.5) for x, y, z in points[::duplicate_every]]
    arr = np.array(pts, dtype=np.float64).reshape(-1, 3)
    assert np.allclose(build_grid(arr, (1.0, 0.2)), _reference_grid(arr, (1.0, 0.2)), atol=1e-5)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.floats(-70.0, 70.0), st.floats(-30.0, 30.0), st.floats(-0.5, 3.0)), max_size=40))
def test_the_region_is_the_occupied_cells_bounding_box(points):
    """`build_grid_region`'s box (from the points) is the bounding box of the grid's
    occupied cells (what the detector used to find by scanning the grid)."""
    from addt_dsl.stack.bev_grid import build_grid_region

    pts = np.array(points, dtype=np.float64).reshape(-1, 3)
    grid, region = build_grid_region(pts, (1.0, 0.0))
    occupied = grid.any(axis=0)
    rows, cols = np.flatnonzero(occupied.any(axis=1)), np.flatnonzero(occupied.any(axis=0))
    expected = (int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1) if len(rows) else (0, 0, 0, 0)
    assert region == expected
    assert np.array_equal(grid, build_grid(pts, (1.0, 0.0)))


@settings(max_examples=30, deadline=None)
@given(st.lists(st.lists(st.tuples(st.floats(-70.0, 70.0), st.floats(-30.0, 30.0), st.floats(-0.5, 3.0)),
                         max_size=12), min_size=1, max_size=6))
def test_a_reused_grid_cleared_only_in_the_last_region_equals_a_fresh_one(scans):
    """Frame after frame into one buffer, clearing only the last frame's region (as the
    learned node does): the same grid and region as building each frame afresh."""
    from addt_dsl.stack.bev_grid import build_grid_region

    out = np.zeros(GRID.shape, dtype=np.float32)
    out[:] = 7.0  # a first frame with dirty=None clears everything
    dirty = None
    for pts in scans:
        points = np.array(pts, dtype=np.float64).reshape(-1, 3)
        fresh, fresh_region = build_grid_region(points, (1.0, 0.0))
        reused, region = build_grid_region(points, (1.0, 0.0), out=out, dirty=dirty)
        assert region == fresh_region
        assert np.array_equal(reused, fresh)
        dirty = region


def _numpy_cells(points_vehicle, sensor_xy, spec=GRID, dtype=np.float32):
    """`build_grid_region` as numpy computed it before its per-cell reductions were a kernel
    (verbatim but for the clearing of a reused grid and the grid's `dtype`), the reference
    for their bits; and the kernel's inputs."""
    from addt_dsl.kernel import log2
    from addt_dsl.stack.bev_grid import COUNT_LOG2_SCALE, RANGE_SCALE_M

    grid = np.zeros(spec.shape, dtype=dtype)
    px, py = points_vehicle[:, 0], points_vehicle[:, 1]
    fx, fy = (px - spec.x_min) / spec.cell_m, (py - spec.y_min) / spec.cell_m
    ix, iy = np.floor(fx).astype(np.int64), np.floor(fy).astype(np.int64)
    keep = (ix >= 0) & (ix < spec.nx) & (iy >= 0) & (iy < spec.ny) & (points_vehicle[:, 2] > spec.ground_m)
    ix, iy, fx, fy = ix[keep], iy[keep], fx[keep], fy[keep]
    px, py, pz = px[keep], py[keep], points_vehicle[keep, 2]
    inputs = (ix, iy, fx, fy, px, py, pz)
    if len(ix) == 0:
        return grid, (0, 0, 0, 0), inputs
    flat = ix * spec.ny + iy
    cells, inv, n = np.unique(flat, return_inverse=True, return_counts=True)
    m = len(cells)
    rx, ry = px - sensor_xy[0], py - sensor_xy[1]
    rnorm = np.maximum(np.hypot(rx, ry), 1e-6)
    views = grid.reshape(CHANNELS, spec.nx * spec.ny)
    views[0, cells] = np.minimum(n, 4) / 4.0
    views[1, cells] = np.bincount(inv, fx - ix - 0.5, m) / n
    views[2, cells] = np.bincount(inv, fy - iy - 0.5, m) / n
    order = np.lexsort((pz, inv))
    by_cell = inv[order]
    last = np.flatnonzero(np.r_[by_cell[1:] != by_cell[:-1], True])
    views[3, cells] = pz[order][last] / 2.0
    views[4, cells] = np.bincount(inv, rx / rnorm, m) / n
    views[5, cells] = np.bincount(inv, ry / rnorm, m) / n
    views[6, cells] = np.bincount(inv, rnorm, m) / n / RANGE_SCALE_M
    views[7, cells] = log2.over(1.0 + n) / COUNT_LOG2_SCALE
    return grid, (int(cells[0]) // spec.ny, int(cells[-1]) // spec.ny + 1, int(iy.min()), int(iy.max()) + 1), inputs


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.floats(-64.0, 64.0), st.floats(-28.0, 28.0), st.floats(-0.5, 3.0),
                          st.integers(0, 5)), max_size=30),
       st.booleans(), st.tuples(st.floats(-3.0, 3.0), st.floats(-1.0, 1.0)))
def test_grid_kernel_gives_the_numpy_grids_bits(points, at_sensor, sensor_xy):
    """The per-cell reductions (`bev_grid._fill_cells`), compiled and interpreted, give the
    bits of the numpy code they replaced: points sharing cells, equal heights in a cell,
    points at the sensor (the 1e-6 floor), points off the grid and below the ground; in the
    detector's float32 grid and, where no rounding to float32 hides a last bit, in float64."""
    from addt_dsl.kernel import bits, interpreted
    from addt_dsl.stack.bev_grid import _fill_cells, build_grid_region

    # Each point with up to 5 more in its cell (a cluster of 1-6: sums of several terms, counts
    # that are no power of 2), every other one at the same height.
    pts = [(x + 0.01 * k, y - 0.007 * k, z if k % 2 else z + 0.001 * k) for x, y, z, more in points
           for k in range(more + 1)]
    pts += [(sensor_xy[0], sensor_xy[1], 1.0)] if at_sensor else []
    arr = np.array(pts, dtype=np.float64).reshape(-1, 3)
    want, want_region, inputs = _numpy_cells(arr, sensor_xy)
    got, region = build_grid_region(arr, sensor_xy)
    assert region == want_region and bits(got) == bits(want)
    with interpreted():
        got, region = build_grid_region(arr, sensor_xy)
    assert region == want_region and bits(got) == bits(want)
    if len(inputs[0]):
        want64, _, _ = _numpy_cells(arr, sensor_xy, dtype=np.float64)
        got64, box = np.zeros_like(want64), np.empty(4, dtype=np.int64)
        _fill_cells(*inputs, float(sensor_xy[0]), float(sensor_xy[1]), GRID.ny, got64.reshape(CHANNELS, -1), box)
        assert bits(got64) == bits(want64) and tuple(box.tolist()) == want_region
