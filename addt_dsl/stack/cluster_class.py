"""The learned detector's class, read from each detection's cluster of returns.

The CNN reads the class at its heatmap peak. For a cyclist the peak often lands where a
car's centre behind the same face would be (about 1.6 m off), and the class read there
is `car`; reading the CNN's class logits over the cells of the object's own points does
not help, as the class head is trained at object centres only and says `pedestrian` or
`cyclist` on a car's faces (docs/stack.md, Evaluation). What does tell a cyclist from a
walker or a car's rear is the returns themselves: how many, how far, how high, how wide
across the line of sight and how deep along it (a per-object classifier on them reaches
0.81-0.94 on true clusters). So each detection's cluster (the returns above the ground
inside its box, 0.3 m to spare, nearer its centre than any other detection's) gives
`FEATURES`, with the CNN's class probabilities at the peak among them, and a
gradient-boosted tree ensemble (scikit-learn's HistGradientBoostingClassifier at
training time, `train --cluster-scenes`) maps them to the class. Its trees ship in the
detector's weights file as flat tensors (`cluster.*`) and are evaluated here in numpy,
all trees and detections at once, one tree level per step.

Pure numpy at run time (no scikit-learn, no torch): `TreeEnsemble.from_state` takes the
tensors as arrays.
"""

from __future__ import annotations

import math

import numpy as np

from addt_dsl.kernel import atan2, exp, hypot, kernel, log2, matmul
from addt_dsl.specs.sensors import EXTRINSICS
from addt_dsl.stack.bev_grid import BOX_CHANNELS, CLASSES, GRID, GridSpec

CLUSTER_MARGIN_M = 0.3  # returns this far outside a detection's box still count as its own
FEATURES = (
    "log2(1 + returns) / 5", "range of the returns' centroid [m] / 60", "highest return [m] / 2",
    "lowest return [m] / 2", "mean height [m] / 2", "extent along the line of sight [m]",
    "extent across it [m]", "spread along it [m]", "spread across it [m]",
    "angular width [rad] * 10", "returns per 1-degree column / 5", "1-degree columns / 10",
    "box centre behind the centroid, along the line of sight [m]",
    "CNN P(car)", "CNN P(truck)", "CNN P(pedestrian)", "CNN P(cyclist)", "CNN confidence",
    "log box length", "log box width", "|sin| of the box axis against the line of sight",
    # Per beam and height: which of the detector lidar's beams meet the object says how tall
    # it is at a given range (a cyclist's 1.7 m against a car's 1.5 m).
    "log2(1 + returns of the -6 deg beam) / 5", "... -3 deg", "... 0 deg", "... +3 deg", "... +6 deg",
    "beams with returns", "share of returns above 1.2 m", "above 1.45 m", "above 1.6 m",
    # The returns' shape in plan view, and the level beam's alone (the one every object meets).
    "major principal spread [m]", "minor principal spread [m]", "|sin| of the major axis against the line of sight",
    "level beam's 1-degree columns / 10", "level beam's extent across the line of sight [m]",
    "highest beam with returns (0: -6 deg ... 4: +6 deg)",
    "box centre across the line of sight from the centroid [m]",
    "log2(1 + own returns up to 1.5 m outside the box) / 5",
)
BEAM_STEP_DEG = 3.0  # the detector lidar's beams: -6, -3, 0, +3, +6 deg (`DETECTOR_LIDAR`)
MOUNT_Z_M = next(p.default for p in EXTRINSICS if p.name == "z")  # the lidar's default mount height
PREFIX = "cluster."  # keys of the ensemble's tensors in the weights file's state dict


def cluster_features(points: np.ndarray, sensor_xy: tuple[float, float], boxes: np.ndarray,
                     box_map: np.ndarray, spec: GridSpec = GRID) -> tuple[np.ndarray, np.ndarray]:
    """(`FEATURES` per detection (K, F), whether it has a cluster (K,)) for the decoded
    `boxes` (K, 7: x, y, heading, length, width, confidence, class) of one frame,
    vehicle-frame `points` and the CNN's `head.box` output (channels, hx, hy).

    One kernel (`_clusters`) walks the detections and their returns; numpy does what its
    own functions define the bits of, once a frame over all returns or detections: the
    returns' angles (numpy's SIMD `arctan2` is not the C library's), the softmax's `exp`
    and the per-beam `log2`; and the principal spreads (`np.cov`'s BLAS product per
    detection, one `eigh` over all detections' 2x2 matrices)."""
    k_boxes = len(boxes)
    feats = np.zeros((k_boxes, len(FEATURES)))
    valid = np.zeros(k_boxes, dtype=bool)
    p = points[points[:, 2] > spec.ground_m] if len(points) else points
    if k_boxes == 0 or len(p) == 0:
        return feats, valid
    p = np.ascontiguousarray(p, dtype=np.float64)
    sx, sy = float(sensor_xy[0]), float(sensor_xy[1])
    gx, gy = p[:, 0] - sx, p[:, 1] - sy
    elevation = atan2.over(p[:, 2] - MOUNT_Z_M, np.hypot(gx, gy))  # [rad] seen from the sensor
    azimuth = atan2.over(gy, gx)
    counts = np.zeros((k_boxes, 8), dtype=np.int64)  # returns, 5 beams, head cell i, j
    shifted = np.zeros((k_boxes, box_map.shape[0] - BOX_CHANNELS))  # class logits less their largest
    unit = np.zeros((k_boxes, 2))  # the line of sight to the centroid
    centred = np.empty(2 * len(p))  # each cluster's (2, n) x, y less their means, as np.cov has them
    offset = np.zeros(k_boxes, dtype=np.int64)
    _clusters(p, elevation, azimuth, sx, sy, np.ascontiguousarray(boxes, dtype=np.float64),
              np.ascontiguousarray(box_map), spec.x_min, spec.y_min, spec.head_cell_m, feats, valid, counts,
              shifted, unit, centred, offset)
    kv = np.flatnonzero(valid)
    if len(kv) == 0:
        return feats, valid
    prob = exp.over(shifted[kv])
    prob /= prob.sum(axis=1, keepdims=True)
    feats[kv, 13:13 + prob.shape[1]] = prob
    feats[kv, 21:26] = log2.over(1 + counts[kv, 1:6]) / 5
    two = kv[counts[kv, 0] >= 2]
    if len(two):
        cov = np.empty((len(two), 2, 2))
        for row, (n, at) in enumerate(zip(counts[two, 0].tolist(), offset[two].tolist())):
            x = centred[at:at + 2 * n].reshape(2, n)
            c = matmul(x, x.T)  # np.cov's product and scale (1 / (n - 1)), in one order on any machine
            c *= 1.0 / (n - 1)
            cov[row] = c
        spread, axes = np.linalg.eigh(cov)  # stacked: each matrix's bits as alone (test)
        for k, (minor, major), ((_, a01), (_, a11)), (ux, uy) in zip(two.tolist(), spread.tolist(), axes.tolist(),
                                                                      unit[two].tolist()):
            feats[k, 30:33] = (math.sqrt(max(major, 0.0)), math.sqrt(max(minor, 0.0)), abs(a01 * uy - a11 * ux))
    return feats, valid


@kernel
def pairwise_sum(a, start, n, stride):
    """`np.sum` of a[start], a[start + stride], ... (n of them) with numpy's bits: its
    pairwise summation (`pairwise_sum`: under 8 terms in order; up to 128 in 8 running
    sums over blocks of 8, combined ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7)),
    then the rest in order; longer halves at a multiple of 8, each summed so), added to
    the reduction's identity 0.0 (so a sum of -0.0s is 0.0). The halving is a loop over
    an explicit stack (kernels do not recurse)."""
    if n <= 128:
        return 0.0 + _pairwise_block(a, start, n, stride)
    starts = np.empty(64, dtype=np.int64)
    sizes = np.empty(64, dtype=np.int64)
    stage = np.zeros(64, dtype=np.int64)  # 0: left half next, 1: right half next, 2: add them
    partial = np.empty(64)
    top, held = 0, 0
    starts[0], sizes[0] = start, n
    while top >= 0:
        m = sizes[top]
        if m <= 128:
            partial[held] = _pairwise_block(a, starts[top], m, stride)
            held += 1
            top -= 1
            continue
        half = m // 2
        half -= half % 8
        if stage[top] == 0:
            stage[top] = 1
            starts[top + 1], sizes[top + 1], stage[top + 1] = starts[top], half, 0
            top += 1
        elif stage[top] == 1:
            stage[top] = 2
            starts[top + 1], sizes[top + 1], stage[top + 1] = starts[top] + half * stride, m - half, 0
            top += 1
        else:
            partial[held - 2] = partial[held - 2] + partial[held - 1]
            held -= 1
            top -= 1
    return 0.0 + partial[0]


@kernel
def _pairwise_block(a, start, n, stride):
    """numpy's `pairwise_sum` of n <= 128 terms (no halving)."""
    if n < 8:
        res = 0.0
        for i in range(n):
            res += a[start + i * stride]
        return res
    r0, r1, r2, r3 = a[start], a[start + stride], a[start + 2 * stride], a[start + 3 * stride]
    r4, r5, r6, r7 = a[start + 4 * stride], a[start + 5 * stride], a[start + 6 * stride], a[start + 7 * stride]
    i = 8
    while i < n - n % 8:
        at = start + i * stride
        r0 += a[at]
        r1 += a[at + stride]
        r2 += a[at + 2 * stride]
        r3 += a[at + 3 * stride]
        r4 += a[at + 4 * stride]
        r5 += a[at + 5 * stride]
        r6 += a[at + 6 * stride]
        r7 += a[at + 7 * stride]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[start + i * stride]
        i += 1
    return res


@kernel
def _distinct_columns(column, idx, m, only_beam, beam, seen, stamp):
    """How many distinct 1-degree `column`s the returns idx[:m] (those on `only_beam` when
    it is >= 0) cover, as len(np.unique(...)) counts them (a NaN once); `seen` (361) holds
    the last stamp each column was met with."""
    count = 0
    nan = False
    for j in range(m):
        i = idx[j]
        if only_beam >= 0 and beam[i] != only_beam:
            continue
        v = column[i]
        if math.isnan(v):
            nan = True
            continue
        at = int(v) + 180
        if seen[at] != stamp:
            seen[at] = stamp
            count += 1
    return count + (1 if nan else 0)


@kernel
def _clusters(p, elevation, azimuth, sx, sy, boxes, box_map, x_min, y_min, head_cell, feats, valid, counts,
              shifted, unit, centred, offset):
    """`cluster_features`' per-detection loop, in the old numpy code's operations and order
    (sums as numpy's pairwise sums): fills `feats` but for the softmax, per-beam and
    principal-spread columns, and for those `counts` (returns, per beam, head cell), the
    class logits at the head cell less their largest (`shifted`), `unit` and each
    cluster's centred x, y in `centred` from `offset`."""
    n_points, k_boxes = p.shape[0], boxes.shape[0]
    hx, hy = box_map.shape[1], box_map.shape[2]
    beam = np.empty(n_points, dtype=np.int64)
    column = np.empty(n_points)  # each return's 1-degree column
    for i in range(n_points):  # np.round(np.degrees(a)): rint (half to even) of a * (180 / pi)
        b = np.rint(elevation[i] * (180.0 / math.pi) / BEAM_STEP_DEG)
        beam[i] = 0 if math.isnan(b) else min(max(int(b) + 2, 0), 4)  # (numpy: NaN -> int64 min -> 0)
        column[i] = np.rint(azimuth[i] * (180.0 / math.pi))
    owner = np.empty(n_points, dtype=np.int64)
    for i in range(n_points):  # np.hypot(...).argmin(axis=1): the first smallest, or the first NaN
        best, best_d = 0, 0.0
        for k in range(k_boxes):
            d = math.hypot(p[i, 0] - boxes[k, 0], p[i, 1] - boxes[k, 1])  # the C library's, as np.hypot
            if math.isnan(d):
                best = k
                break
            if k == 0 or d < best_d:
                best, best_d = k, d
        owner[i] = best
    idx = np.empty(n_points, dtype=np.int64)
    q = np.empty(3 * n_points)
    along = np.empty(n_points)
    across = np.empty(n_points)
    square = np.empty(n_points)
    seen = np.full(361, -1, dtype=np.int64)
    used = 0
    for k in range(k_boxes):
        x, y, heading, length, width, conf = boxes[k, 0], boxes[k, 1], boxes[k, 2], boxes[k, 3], boxes[k, 4], \
            boxes[k, 5]
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(heading) and math.isfinite(length)
                and math.isfinite(width)):
            continue  # a fault's NaN box: keep the CNN's class
        c, s = math.cos(heading), math.sin(heading)
        in_a, in_b = 0.5 * length + CLUSTER_MARGIN_M, 0.5 * width + CLUSTER_MARGIN_M
        ring_a, ring_b = 0.5 * length + 1.5, 0.5 * width + 1.5
        m, ring = 0, 0
        for i in range(n_points):
            if owner[i] != k:
                continue
            dx, dy = p[i, 0] - x, p[i, 1] - y
            a, b = abs(c * dx + s * dy), abs(c * dy - s * dx)
            if a < in_a and b < in_b:
                idx[m] = i
                q[3 * m], q[3 * m + 1], q[3 * m + 2] = p[i, 0], p[i, 1], p[i, 2]
                m += 1
            elif a < ring_a and b < ring_b:
                ring += 1
        if m == 0:
            continue
        fi = math.floor((x - x_min) / head_cell)  # clamped as floats: a fault's huge x must not wrap
        fj = math.floor((y - y_min) / head_cell)
        ci = 0 if fi < 0.0 else (hx - 1 if fi > hx - 1 else int(fi))
        cj = 0 if fj < 0.0 else (hy - 1 if fj > hy - 1 else int(fj))
        counts[k, 6], counts[k, 7] = ci, cj
        top, nan = -math.inf, False  # np.max: NaN if any
        for c in range(shifted.shape[1]):
            v = float(box_map[BOX_CHANNELS + c, ci, cj])
            nan = nan or math.isnan(v)
            if v > top:
                top = v
        if nan:
            top = math.nan
        for c in range(shifted.shape[1]):
            shifted[k, c] = float(box_map[BOX_CHANNELS + c, ci, cj]) - top
        cx, cy = pairwise_sum(q, 0, m, 3) / m, pairwise_sum(q, 1, m, 3) / m
        rx, ry = cx - sx, cy - sy
        r = hypot(rx, ry)
        if 1e-3 > r:
            r = 1e-3
        ux, uy = rx / r, ry / r
        unit[k, 0], unit[k, 1] = ux, uy
        z_max, z_min = q[2], q[2]
        above12, above145, above16 = 0, 0, 0
        top_beam, level = 0, 0
        for j in range(m):
            i = idx[j]
            gx, gy = q[3 * j] - sx, q[3 * j + 1] - sy
            along[j] = gx * ux + gy * uy
            across[j] = gy * ux - gx * uy
            z = q[3 * j + 2]
            if z > z_max:
                z_max = z
            if z < z_min:
                z_min = z
            above12 += z > 1.2
            above145 += z > 1.45
            above16 += z > 1.6
            bq = beam[i]
            counts[k, 1 + bq] += 1
            if bq > top_beam:
                top_beam = bq
        counts[k, 0] = m
        al_max, al_min, ac_max, ac_min = along[0], along[0], across[0], across[0]
        lv_max, lv_min = 0.0, 0.0
        for j in range(m):
            if along[j] > al_max:
                al_max = along[j]
            if along[j] < al_min:
                al_min = along[j]
            if across[j] > ac_max:
                ac_max = across[j]
            if across[j] < ac_min:
                ac_min = across[j]
            if beam[idx[j]] == 2:
                if level == 0 or across[j] > lv_max:
                    lv_max = across[j]
                if level == 0 or across[j] < lv_min:
                    lv_min = across[j]
                level += 1
        columns = _distinct_columns(column, idx, m, -1, beam, seen, 2 * k)
        level_columns = _distinct_columns(column, idx, m, 2, beam, seen, 2 * k + 1) if level else 0
        wide = ac_max - ac_min
        stds = np.empty(2)
        for w in range(2):
            v = along if w == 0 else across
            mean = pairwise_sum(v, 0, m, 1) / m
            for j in range(m):
                d = v[j] - mean
                square[j] = d * d
            stds[w] = math.sqrt(pairwise_sum(square, 0, m, 1) / m)
        if m >= 2:  # np.cov's input: x, y rows less their means, which numpy sums over the
            # rows of its (2, n) copy side by side, so in order (not pairwise: test)
            mx, my = 0.0, 0.0
            for j in range(m):
                mx += q[3 * j]
                my += q[3 * j + 1]
            mx, my = mx / m, my / m
            offset[k] = used
            for j in range(m):
                centred[used + j] = q[3 * j] - mx
                centred[used + m + j] = q[3 * j + 1] - my
            used += 2 * m
        beams = 0
        for b in range(5):
            beams += counts[k, 1 + b] > 0
        f = feats[k]
        f[0] = math.log2(1 + m) / 5
        f[1] = r / 60
        f[2] = z_max / 2
        f[3] = z_min / 2
        f[4] = pairwise_sum(q, 2, m, 3) / m / 2
        f[5] = al_max - al_min
        f[6] = wide
        f[7] = stds[0]
        f[8] = stds[1]
        f[9] = wide / r * 10
        f[10] = m / columns / 5
        f[11] = columns / 10
        f[12] = (x - cx) * ux + (y - cy) * uy
        f[17] = conf
        f[18] = math.log(length)
        f[19] = math.log(width)
        f[20] = abs(math.sin(heading - math.atan2(ry, rx)))
        f[26] = beams
        f[27] = above12 / m
        f[28] = above145 / m
        f[29] = above16 / m
        f[33] = level_columns / 10
        f[34] = lv_max - lv_min if level else 0.0
        f[35] = top_beam
        f[36] = (x - cx) * uy - (y - cy) * ux
        f[37] = math.log2(1 + ring) / 5
        valid[k] = True


class TreeEnsemble:
    """Gradient-boosted trees as flat arrays: node `n` splits on `feature[n]` (go left when
    the value is at most `threshold[n]`) unless `leaf[n]`, then it adds `value[n]`; `roots`
    (iterations, classes) are the trees' first nodes; class logits are `baseline` plus the
    sum of each class's trees."""

    def __init__(self, feature, threshold, left, right, leaf, value, roots, baseline, depth: int):
        self.feature = np.ascontiguousarray(feature, dtype=np.int64)
        self.threshold = np.ascontiguousarray(threshold, dtype=np.float64)
        self.left = np.ascontiguousarray(left, dtype=np.int64)
        self.right = np.ascontiguousarray(right, dtype=np.int64)
        self.leaf = np.ascontiguousarray(leaf, dtype=bool)
        self.value = np.ascontiguousarray(value, dtype=np.float64)
        self.roots = np.ascontiguousarray(roots, dtype=np.int64)
        self.baseline = np.ascontiguousarray(baseline, dtype=np.float64)
        self.depth = int(depth)
        # The walk's nodes packed 16 bytes each, 4 to a cache line (the six arrays above touch
        # up to six lines a node; between frames the ~2 MB of them leave the cache): per node
        # the threshold, or a leaf's value, and its feature | left << 16 | right << 40
        # (feature 0xFFFF: a leaf).
        n = len(self.feature)
        if n >= 1 << 24 or (len(self.feature) and int(self.feature.max(initial=0)) >= 0xFFFF):
            raise ValueError(f"a tree ensemble of {n} nodes: at most 2**24 nodes and 65535 features")
        level = self.roots.reshape(-1)  # the walk stops at `depth` splits: every tree must end by then
        for _ in range(self.depth):
            inner = level[~self.leaf[level]]
            level = np.concatenate([self.left[inner], self.right[inner]])
        if not self.leaf[level].all():
            raise ValueError(f"a tree of the ensemble is deeper than its depth {self.depth}")
        packed = np.empty((n, 2), dtype=np.int64)
        packed[:, 0] = np.where(self.leaf, self.value, self.threshold).view(np.int64)
        packed[:, 1] = np.where(self.leaf, 0xFFFF, self.feature) | (np.where(self.leaf, 0, self.left) << 16) \
            | (np.where(self.leaf, 0, self.right) << 40)
        self._packed, self._split = packed, packed.view(np.float64)

    @classmethod
    def from_sklearn(cls, clf) -> TreeEnsemble:
        """From a fitted HistGradientBoostingClassifier (numerical features, no missing values)."""
        feature, threshold, left, right, leaf, value, roots = [], [], [], [], [], [], []
        depth = 0
        for trees in clf._predictors:  # per iteration, one tree per class
            row = []
            for tree in trees:
                nodes = tree.nodes
                base = sum(len(a) for a in feature)
                row.append(base)
                feature.append(nodes["feature_idx"])
                threshold.append(nodes["num_threshold"])
                left.append(np.where(nodes["is_leaf"], 0, nodes["left"] + base))
                right.append(np.where(nodes["is_leaf"], 0, nodes["right"] + base))
                leaf.append(nodes["is_leaf"])
                value.append(nodes["value"])
                depth = max(depth, int(nodes["depth"].max()))
            roots.append(row)
        baseline = np.asarray(clf._baseline_prediction, dtype=np.float64).reshape(-1)
        return cls(*(np.concatenate(a) for a in (feature, threshold, left, right, leaf, value)),
                   np.array(roots), baseline, depth)

    def state(self) -> dict[str, np.ndarray]:
        """The arrays to store (narrow integer types: ~27 bytes a node)."""
        return {"feature": self.feature.astype(np.int16), "threshold": self.threshold,
                "left": self.left.astype(np.int32), "right": self.right.astype(np.int32), "leaf": self.leaf,
                "value": self.value, "roots": self.roots.astype(np.int32), "baseline": self.baseline,
                "depth": np.array(self.depth, dtype=np.int64)}

    @classmethod
    def from_state(cls, state: dict[str, np.ndarray]) -> TreeEnsemble:
        return cls(**{k: (int(np.asarray(v).item()) if k == "depth" else v) for k, v in state.items()})

    def logits(self, x: np.ndarray) -> np.ndarray:
        """(K, F) features -> (K, classes) logits (a NaN feature goes right, as `<=` says)."""
        x = np.ascontiguousarray(x, dtype=np.float64)
        out = np.zeros((len(x), len(self.baseline)))
        if len(x):
            _tree_logits(x, self._split, self._packed, self.roots, self.baseline, self.depth, out)
        return out


@kernel
def _tree_logits(x, split, links, roots, baseline, depth, out):
    """Each detection's walk down every tree (at most `depth` splits; `split[:, 0]` and
    `links[:, 1]`: `TreeEnsemble`'s packed nodes); a class's logit is its baseline plus its
    trees' leaf values summed in iteration order from the first, onto 0.0 (as numpy's sum
    over the iterations axis adds them: test). Tree by tree, all detections through one
    (their walks share its nodes' cache lines); `out` (K, classes) zeros on entry."""
    iterations, classes = roots.shape
    for it in range(iterations):
        for c in range(classes):
            root = roots[it, c]
            for k in range(x.shape[0]):
                node = root
                for _ in range(depth):
                    word = links[node, 1]
                    feature = word & 0xFFFF
                    if feature == 0xFFFF:
                        break
                    node = (word >> 16) & 0xFFFFFF if x[k, feature] <= split[node, 0] else word >> 40
                out[k, c] += split[node, 0]
    for k in range(x.shape[0]):
        for c in range(classes):
            out[k, c] = baseline[c] + out[k, c]


def reclass(boxes: np.ndarray, points: np.ndarray, sensor_xy: tuple[float, float], box_map: np.ndarray,
            ensemble: TreeEnsemble, offsets: np.ndarray | None = None) -> np.ndarray:
    """`boxes` with column 6 (class) read from each detection's cluster (in place; a
    detection with no returns of its own keeps the CNN's class). `offsets`: added to the
    ensemble's class logits (logit adjustment, as the CNN's)."""
    if len(boxes) == 0:
        return boxes
    feats, valid = cluster_features(points, sensor_xy, boxes, box_map)
    if valid.any():
        logits = ensemble.logits(feats[valid])
        if offsets is not None:
            logits = logits + offsets
        boxes[valid, 6] = logits.argmax(axis=1)
    return boxes


def fit(features: np.ndarray, labels: np.ndarray, seed: int, iterations: int = 200):
    """A fitted HistGradientBoostingClassifier (scikit-learn, a core dependency) on cluster
    features and the matched boxes' classes; the seed and the data fix it (no early stopping,
    no subsampling, one OpenMP thread: on shared cores more threads spin, and their
    partial sums could differ in the last bits)."""
    from sklearn.ensemble import HistGradientBoostingClassifier
    from threadpoolctl import threadpool_limits

    missing = set(range(len(CLASSES))) - set(np.asarray(labels).tolist())
    if missing:  # the trees' outputs are the classes seen, in order: every class must be
        raise ValueError("no detection of class " + ", ".join(CLASSES[k] for k in sorted(missing))
                         + " to fit the cluster class reader on: use more scans")
    clf = HistGradientBoostingClassifier(max_iter=iterations, early_stopping=False, random_state=seed)
    with threadpool_limits(1):
        return clf.fit(features, labels)


def labelled_clusters(samples, detect_raw, min_hits: int = 2, match_m: float = 2.0):
    """(features, classes, ranges [m]) of the detections that match a box with at least
    `min_hits` returns (as `evaluate` matches them) over `samples`; `detect_raw(points,
    sensor_xy)` -> (boxes, head.box map) with the CNN's own classes."""
    from addt_dsl.stack.synth import in_grid

    feats, labels, ranges = [], [], []
    for s in samples:
        boxes, box_map = detect_raw(s.points, s.sensor_xy)
        keep = in_grid(s.boxes)
        gt, hits, cls = s.boxes[keep], s.hits[keep], s.classes[keep]
        if not len(boxes) or not len(gt):
            continue
        f, valid = cluster_features(s.points, s.sensor_xy, boxes, box_map)
        taken = np.zeros(len(gt), dtype=bool)
        for k, row in enumerate(boxes):
            d = np.hypot(gt[:, 0] - row[0], gt[:, 1] - row[1])
            d[taken] = np.inf
            m = int(np.argmin(d))
            if d[m] >= match_m:
                continue
            taken[m] = True
            if hits[m] >= min_hits and valid[k]:
                feats.append(f[k])
                labels.append(int(cls[m]))
                ranges.append(math.hypot(gt[m, 0], gt[m, 1]))
    return (np.array(feats).reshape(-1, len(FEATURES)), np.array(labels, dtype=np.int64), np.array(ranges))

