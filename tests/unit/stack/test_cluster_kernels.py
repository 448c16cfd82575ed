"""`cluster_class`'s kernels give the bits of the numpy code they replace (copied here as the
oracle, verbatim but for numpy's `arctan2`, `exp`, `log2` and the covariance's product, which
are the C library's and `kernel.matmul`'s on every machine now) and compiled, of their own
Python; `pairwise_sum` is numpy's sum."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from addt_dsl.kernel import atan2, exp, interpreted, log2, matmul
from addt_dsl.stack import cluster_class
from addt_dsl.stack.bev_grid import BOX_CHANNELS, GRID, GridSpec
from addt_dsl.stack.cluster_class import CLUSTER_MARGIN_M, FEATURES, MOUNT_Z_M, BEAM_STEP_DEG, pairwise_sum


# ---------------------------------------------------------------- the numpy code replaced (verbatim)

def cov_in_order(x: np.ndarray) -> np.ndarray:
    """np.cov's steps (mean by np.average, the centred rows' product, 1 / (n - 1)), the
    product summed in one order (`kernel.matmul`) as the features now take it."""
    x = np.array(x, dtype=np.float64)
    x -= np.average(x, axis=1)[:, None]
    c = matmul(x, x.T)
    c *= np.true_divide(1, x.shape[1] - 1)
    return c


def old_cluster_features(points: np.ndarray, sensor_xy: tuple[float, float], boxes: np.ndarray,
                         box_map: np.ndarray, spec: GridSpec = GRID) -> tuple[np.ndarray, np.ndarray]:
    k_boxes = len(boxes)
    feats = np.zeros((k_boxes, len(FEATURES)))
    valid = np.zeros(k_boxes, dtype=bool)
    p = points[points[:, 2] > spec.ground_m] if len(points) else points
    if k_boxes == 0 or len(p) == 0:
        return feats, valid
    p = p.astype(np.float64)
    owner = np.hypot(p[:, None, 0] - boxes[None, :, 0], p[:, None, 1] - boxes[None, :, 1]).argmin(axis=1)
    hx, hy = box_map.shape[1:]
    sx, sy = sensor_xy
    beam = np.clip(np.round(np.degrees(atan2.over(p[:, 2] - MOUNT_Z_M, np.hypot(p[:, 0] - sx, p[:, 1] - sy)))
                            / BEAM_STEP_DEG).astype(np.int64) + 2, 0, 4)
    for k, (x, y, heading, length, width, conf, _) in enumerate(boxes.tolist()):
        if not all(map(math.isfinite, (x, y, heading, length, width))):
            continue  # a fault's NaN box: keep the CNN's class
        c, s = math.cos(heading), math.sin(heading)
        dx, dy = p[:, 0] - x, p[:, 1] - y
        a, b = np.abs(c * dx + s * dy), np.abs(c * dy - s * dx)
        inbox = (a < 0.5 * length + CLUSTER_MARGIN_M) & (b < 0.5 * width + CLUSTER_MARGIN_M)
        own = (owner == k) & inbox
        q = p[own]
        if len(q) == 0:
            continue
        i = min(max(int(math.floor((x - spec.x_min) / spec.head_cell_m)), 0), hx - 1)
        j = min(max(int(math.floor((y - spec.y_min) / spec.head_cell_m)), 0), hy - 1)
        logits = box_map[BOX_CHANNELS:, i, j].astype(np.float64)
        prob = exp.over(logits - logits.max())
        prob /= prob.sum()
        cx, cy = q[:, 0].mean(), q[:, 1].mean()
        rx, ry = cx - sx, cy - sy
        r = max(math.hypot(rx, ry), 1e-3)
        ux, uy = rx / r, ry / r
        along = (q[:, 0] - sx) * ux + (q[:, 1] - sy) * uy
        across = (q[:, 1] - sy) * ux - (q[:, 0] - sx) * uy
        columns = len(np.unique(np.round(np.degrees(atan2.over(q[:, 1] - sy, q[:, 0] - sx)))))
        wide = float(across.max() - across.min())
        bq = beam[own]
        per_beam = np.bincount(bq, minlength=5)
        if len(q) >= 2:
            spread, axes = np.linalg.eigh(cov_in_order(q[:, :2].T))
            major, minor = math.sqrt(max(spread[1], 0.0)), math.sqrt(max(spread[0], 0.0))
            major_sin = abs(axes[0, 1] * uy - axes[1, 1] * ux)
        else:
            major = minor = major_sin = 0.0
        level = bq == 2
        if level.any():
            level_columns = len(np.unique(np.round(np.degrees(atan2.over(q[level, 1] - sy, q[level, 0] - sx)))))
            level_wide = float(across[level].max() - across[level].min())
        else:
            level_columns, level_wide = 0, 0.0
        ring = (owner == k) & ~inbox & (a < 0.5 * length + 1.5) & (b < 0.5 * width + 1.5)
        z = q[:, 2]
        feats[k] = (math.log2(1 + len(q)) / 5, r / 60, q[:, 2].max() / 2, q[:, 2].min() / 2, q[:, 2].mean() / 2,
                    along.max() - along.min(), wide, along.std(), across.std(), wide / r * 10,
                    len(q) / columns / 5, columns / 10, (x - cx) * ux + (y - cy) * uy, *prob, conf,
                    math.log(length), math.log(width), abs(math.sin(heading - math.atan2(ry, rx))),
                    *(log2.over(1 + per_beam) / 5), (per_beam > 0).sum(), (z > 1.2).mean(), (z > 1.45).mean(),
                    (z > 1.6).mean(), major, minor, major_sin, level_columns / 10, level_wide, bq.max(),
                    (x - cx) * uy - (y - cy) * ux, math.log2(1 + int(ring.sum())) / 5)
        valid[k] = True
    return feats, valid


def old_logits(self, x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, dtype=np.float64)
    if len(x) == 0:
        return np.zeros((0, len(self.baseline)))
    node = np.broadcast_to(self.roots.reshape(-1)[:, None], (self.roots.size, len(x))).copy()
    rows = np.arange(len(x))[None, :]
    for _ in range(self.depth):
        go_left = x[rows, self.feature[node]] <= self.threshold[node]
        node = np.where(self.leaf[node], node, np.where(go_left, self.left[node], self.right[node]))
    sums = self.value[node].reshape(*self.roots.shape, len(x)).sum(axis=0)  # (classes, K)
    return self.baseline[None, :] + sums.T


# ---------------------------------------------------------------- helpers

def bits(a) -> list:
    """float64 bit patterns, every NaN as one pattern (a compiled kernel may flip a NaN's sign)."""
    a = np.asarray(a, dtype=np.float64)
    out = a.view(np.int64).copy()
    out[np.isnan(a)] = 0x7FF8000000000000
    return out.tolist()


@pytest.fixture(scope="module")
def shipped():
    pytest.importorskip("torch")
    from addt_dsl.stack.learned import load_cluster_classes

    ensemble, _ = load_cluster_classes()
    return ensemble


finite = st.floats(-30.0, 30.0, allow_nan=False, allow_infinity=False)
odd = st.sampled_from([math.nan, math.inf, -math.inf, -0.0, 0.0, 1e-300])


@st.composite
def frames(draw):
    """A frame: returns clustered around boxes (some on a box's edge, some NaN or inf),
    boxes (some NaN, tiny, rotated), a head map (NaN/inf logits at times)."""
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    k = draw(st.integers(1, 7))
    n = draw(st.integers(0, 300))
    boxes = np.column_stack([rng.uniform(-50, 50, k), rng.uniform(-20, 20, k), rng.uniform(-3.2, 3.2, k),
                             rng.uniform(0.3, 12, k), rng.uniform(0.3, 3, k), rng.uniform(0, 1, k),
                             rng.integers(0, 4, k)])
    if draw(st.booleans()):
        boxes[draw(st.integers(0, k - 1)), draw(st.integers(0, 4))] = draw(odd)
    centre = boxes[rng.integers(0, k, n), :2]
    spread = draw(st.sampled_from([0.05, 0.5, 2.0]))
    points = np.column_stack([centre + rng.normal(0, spread, (n, 2)), rng.uniform(0.0, 2.5, n)])
    if n and draw(st.booleans()):
        points[rng.integers(0, n, 2)] = points[0]  # repeated returns: a zero spread
    if n and draw(st.booleans()):
        points[draw(st.integers(0, n - 1)), draw(st.integers(0, 2))] = draw(odd)
    box_map = rng.normal(0, 4, (BOX_CHANNELS + 4, *GRID.head_shape)).astype(np.float32)
    if draw(st.booleans()):
        box_map[BOX_CHANNELS + draw(st.integers(0, 3))] = draw(odd)
    dtype = draw(st.sampled_from([np.float64, np.float32]))
    return points.astype(dtype), (draw(finite) / 10, draw(finite) / 30), boxes, box_map


def _no_error(fn, *args):
    try:
        with np.errstate(all="ignore"):
            return fn(*args)
    except ValueError:  # Python's math.log of a zero length raises (compiled: -inf)
        return None


# ---------------------------------------------------------------- tests

@settings(max_examples=150, deadline=None)
@given(frames())
def test_cluster_features_give_the_numpy_codes_bits(frame):
    want = _no_error(old_cluster_features, *frame)
    if want is None:
        return
    got = _no_error(cluster_class.cluster_features, *frame)
    assert got[1].tolist() == want[1].tolist()
    assert bits(got[0]) == bits(want[0])


@settings(max_examples=60, deadline=None)
@given(frames())
def test_cluster_kernel_compiled_gives_its_python_bits(frame):
    with interpreted():
        want = _no_error(cluster_class.cluster_features, *frame)  # Python's math.log(0.0) raises
    if want is None:
        return
    with np.errstate(all="ignore"):
        got = cluster_class.cluster_features(*frame)
    assert got[1].tolist() == want[1].tolist()
    assert bits(got[0]) == bits(want[0])


def test_big_clusters_and_a_lone_return():
    """Clusters past 128 returns (numpy's pairwise sums halve them) and of one return."""
    rng = np.random.default_rng(5)
    boxes = np.array([[20.0, 2.0, 0.3, 10.0, 3.0, 0.9, 0.0], [-15.0, -4.0, 0.0, 1.0, 1.0, 0.7, 2.0]])
    points = np.vstack([np.column_stack([20.0 + rng.uniform(-4, 4, 700), 2.0 + rng.uniform(-1, 1, 700),
                                         rng.uniform(0.4, 2.0, 700)]), [[-15.0, -4.0, 1.1]]])
    box_map = rng.normal(0, 2, (BOX_CHANNELS + 4, *GRID.head_shape)).astype(np.float32)
    got, want = cluster_class.cluster_features(points, (1.0, 0.0), boxes, box_map), \
        old_cluster_features(points, (1.0, 0.0), boxes, box_map)
    assert got[1].tolist() == want[1].tolist() == [True, True]
    assert bits(got[0]) == bits(want[0])


@pytest.mark.parametrize("seed", [0, 1])
def test_features_and_classes_on_the_detectors_own_frames(shipped, seed):
    """Scans of the synthetic scenes through the shipped detector: its boxes and head map,
    the features and the class logits as the numpy code gave them."""
    from addt_dsl.stack.learned import LearnedPerception
    from addt_dsl.stack.synth import generate

    node = LearnedPerception({})
    checked = 0
    for sample in generate(4, 900 + seed):
        boxes, box_map = node.detect_raw(sample.points, sample.sensor_xy)
        if not len(boxes):
            continue
        got = cluster_class.cluster_features(sample.points, sample.sensor_xy, boxes, box_map)
        want = old_cluster_features(sample.points, sample.sensor_xy, boxes, box_map)
        assert got[1].tolist() == want[1].tolist() and bits(got[0]) == bits(want[0])
        assert bits(shipped.logits(got[0][got[1]])) == bits(old_logits(shipped, want[0][want[1]]))
        checked += int(got[1].sum())
    assert checked > 0


features = st.floats(-5.0, 5.0) | odd


@settings(max_examples=80, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 40), st.lists(st.tuples(st.integers(0, 39), st.integers(0, 37),
                                                                           odd), max_size=20))
def test_logits_give_the_numpy_codes_bits(shipped, seed, k, specials):
    """The shipped ensemble over random features, NaN (goes right) and inf among them."""
    x = np.random.default_rng(seed).normal(0, 1.5, (k, len(FEATURES)))
    for row, col, v in specials:
        x[row % k, col] = v
    got = shipped.logits(x)
    assert bits(got) == bits(old_logits(shipped, x))
    with interpreted():
        assert bits(shipped.logits(x)) == bits(got)


def test_logits_sum_the_iterations_in_order():
    """A toy ensemble whose leaf values' sum depends on the order: numpy's sum over the
    iterations axis adds them from the first, as the kernel does (and -0.0s give -0.0 + 0.0)."""
    values = np.array([1e16, 1.0, -1e16, 1.0, -0.0])
    for order in ([0, 1, 2, 3], [2, 3, 0, 1], [1, 0, 3, 2], [4, 4, 4, 4]):
        n = len(order)
        ens = cluster_class.TreeEnsemble(np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(n), np.ones(n, bool),
                                         values[order], np.arange(n).reshape(n, 1), np.array([-0.0]), 3)
        for k in (1, 2, 9):
            x = np.zeros((k, len(FEATURES)))
            assert bits(ens.logits(x)) == bits(old_logits(ens, x))
    assert cluster_class.TreeEnsemble(*([np.zeros(1)] * 4), np.ones(1, bool), np.zeros(1), [[0]], [0.0], 1) \
        .logits(np.zeros((0, len(FEATURES)))).shape == (0, 1)


@pytest.mark.parametrize("strided", [False, True])
def test_pairwise_sum_is_numpys(strided):
    """np.sum, np.mean and np.std's sums over lengths 0..1000, columns of an (n, 3) array
    or contiguous, -0.0s and mixed magnitudes among them."""
    rng = np.random.default_rng(7)
    for n in range(0, 1001):
        a = rng.normal(0, 1, (n, 3)) * 10.0 ** rng.integers(-6, 7, (n, 3))
        if n % 11 == 0:
            a[:] = -0.0
        flat = a.ravel()
        col, start, stride = (a[:, 1], 1, 3) if strided else (np.ascontiguousarray(a[:, 1]), 0, 1)
        src = flat if strided else col
        got = pairwise_sum(src, start, n, stride)
        assert bits(got) == bits(col.sum()), n
        if n:
            assert bits(got / n) == bits(col.mean())
            mean = got / n
            sq = (col - mean) * (col - mean)
            assert bits(math.sqrt(pairwise_sum(np.ascontiguousarray(sq), 0, n, 1) / n)) == bits(col.std())
        if n % 97 == 0:
            with interpreted():
                assert bits(pairwise_sum(src, start, n, stride)) == bits(got)


def test_stacked_eigh_gives_each_matrixs_bits():
    """`cluster_features` solves all detections' 2x2 covariances in one `eigh`."""
    rng = np.random.default_rng(3)
    mats = [np.cov((rng.normal(0, 1, (int(m), 2)) * rng.uniform(0.01, 5, 2)).T) for m in rng.integers(2, 200, 60)]
    spread, axes = np.linalg.eigh(np.array(mats))
    for k, m in enumerate(mats):
        s, a = np.linalg.eigh(m)
        assert bits(s) == bits(spread[k]) and bits(a) == bits(axes[k])


def test_an_ensemble_deeper_than_its_depth_is_refused(shipped):
    """The kernel's walk stops at `depth` splits, where the numpy walk read an inner node's
    value: an ensemble whose trees go deeper is not loaded."""
    state = shipped.state()
    with pytest.raises(ValueError, match="deeper than its depth 5"):
        cluster_class.TreeEnsemble.from_state({**state, "depth": np.array(5)})
    assert cluster_class.TreeEnsemble.from_state(state).depth == shipped.depth


def test_a_zero_length_box_gives_minus_inf_not_an_error():
    """A fault can make a box's length exp(-huge) = 0.0 with returns within its margin:
    the numpy code's math.log raised there (the run failed); its log is now -inf."""
    points = np.array([[10.0, 0.0, 1.0], [10.1, 0.1, 1.2]])
    boxes = np.array([[10.0, 0.0, 0.0, 0.0, 1.0, 0.9, 0.0]])
    box_map = np.zeros((BOX_CHANNELS + 4, *GRID.head_shape), dtype=np.float32)
    with pytest.raises(ValueError):
        old_cluster_features(points, (0.0, 0.0), boxes, box_map)
    feats, valid = cluster_class.cluster_features(points, (0.0, 0.0), boxes, box_map)
    assert valid.tolist() == [True] and feats[0, 18] == -math.inf and feats[0, 19] == 0.0
