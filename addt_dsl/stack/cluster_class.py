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
    vehicle-frame `points` and the CNN's `head.box` output (channels, hx, hy)."""
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
    beam = np.clip(np.round(np.degrees(np.arctan2(p[:, 2] - MOUNT_Z_M, np.hypot(p[:, 0] - sx, p[:, 1] - sy)))
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
        prob = np.exp(logits - logits.max())
        prob /= prob.sum()
        cx, cy = q[:, 0].mean(), q[:, 1].mean()
        rx, ry = cx - sx, cy - sy
        r = max(math.hypot(rx, ry), 1e-3)
        ux, uy = rx / r, ry / r
        along = (q[:, 0] - sx) * ux + (q[:, 1] - sy) * uy
        across = (q[:, 1] - sy) * ux - (q[:, 0] - sx) * uy
        columns = len(np.unique(np.round(np.degrees(np.arctan2(q[:, 1] - sy, q[:, 0] - sx)))))
        wide = float(across.max() - across.min())
        bq = beam[own]
        per_beam = np.bincount(bq, minlength=5)
        if len(q) >= 2:
            spread, axes = np.linalg.eigh(np.cov(q[:, :2].T))
            major, minor = math.sqrt(max(spread[1], 0.0)), math.sqrt(max(spread[0], 0.0))
            major_sin = abs(axes[0, 1] * uy - axes[1, 1] * ux)
        else:
            major = minor = major_sin = 0.0
        level = bq == 2
        if level.any():
            level_columns = len(np.unique(np.round(np.degrees(np.arctan2(q[level, 1] - sy, q[level, 0] - sx)))))
            level_wide = float(across[level].max() - across[level].min())
        else:
            level_columns, level_wide = 0, 0.0
        ring = (owner == k) & ~inbox & (a < 0.5 * length + 1.5) & (b < 0.5 * width + 1.5)
        z = q[:, 2]
        feats[k] = (math.log2(1 + len(q)) / 5, r / 60, q[:, 2].max() / 2, q[:, 2].min() / 2, q[:, 2].mean() / 2,
                    along.max() - along.min(), wide, along.std(), across.std(), wide / r * 10,
                    len(q) / columns / 5, columns / 10, (x - cx) * ux + (y - cy) * uy, *prob, conf,
                    math.log(length), math.log(width), abs(math.sin(heading - math.atan2(ry, rx))),
                    *(np.log2(1 + per_beam) / 5), (per_beam > 0).sum(), (z > 1.2).mean(), (z > 1.45).mean(),
                    (z > 1.6).mean(), major, minor, major_sin, level_columns / 10, level_wide, bq.max(),
                    (x - cx) * uy - (y - cy) * ux, math.log2(1 + int(ring.sum())) / 5)
        valid[k] = True
    return feats, valid


class TreeEnsemble:
    """Gradient-boosted trees as flat arrays: node `n` splits on `feature[n]` (go left when
    the value is at most `threshold[n]`) unless `leaf[n]`, then it adds `value[n]`; `roots`
    (iterations, classes) are the trees' first nodes; class logits are `baseline` plus the
    sum of each class's trees."""

    def __init__(self, feature, threshold, left, right, leaf, value, roots, baseline, depth: int):
        self.feature = np.asarray(feature, dtype=np.int64)
        self.threshold = np.asarray(threshold, dtype=np.float64)
        self.left = np.asarray(left, dtype=np.int64)
        self.right = np.asarray(right, dtype=np.int64)
        self.leaf = np.asarray(leaf, dtype=bool)
        self.value = np.asarray(value, dtype=np.float64)
        self.roots = np.asarray(roots, dtype=np.int64)
        self.baseline = np.asarray(baseline, dtype=np.float64)
        self.depth = int(depth)

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
        """(K, F) features -> (K, classes) logits."""
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

