"""The class read from each detection's cluster of returns (`cluster_class`)."""

import math

import numpy as np
import pytest

from addt_dsl.stack import cluster_class
from addt_dsl.stack.bev_grid import BOX_CHANNELS, GRID


def _toy(seed=0, n=600):
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(n, len(cluster_class.FEATURES)))
    y = (x[:, 0] > 0).astype(int) + 2 * (x[:, 3] + 0.5 * x[:, 5] > 0.3).astype(int)
    return x, y


def test_flat_trees_give_scikit_learns_logits_and_survive_storing():
    x, y = _toy()
    clf = cluster_class.fit(x, y, seed=0, iterations=25)
    ensemble = cluster_class.TreeEnsemble.from_sklearn(clf)
    test, _ = _toy(seed=1, n=300)
    expected = clf._raw_predict(test)
    assert np.allclose(ensemble.logits(test), expected, rtol=0, atol=1e-12)
    assert np.array_equal(ensemble.logits(test).argmax(axis=1), clf.predict(test))
    stored = cluster_class.TreeEnsemble.from_state(ensemble.state())
    assert np.array_equal(stored.logits(test), ensemble.logits(test))
    assert ensemble.logits(np.zeros((0, len(cluster_class.FEATURES)))).shape == (0, 4)


def test_fitting_needs_every_class():
    x, y = _toy()
    with pytest.raises(ValueError, match="cyclist"):
        cluster_class.fit(x, np.minimum(y, 2), seed=0, iterations=2)


def test_same_seed_and_data_same_trees():
    x, y = _toy()
    a, b = (cluster_class.TreeEnsemble.from_sklearn(cluster_class.fit(x, y, seed=3, iterations=10)) for _ in range(2))
    assert all(np.array_equal(u, v) for u, v in zip(a.state().values(), b.state().values()))


def _head_map(cls_at_peak: int) -> np.ndarray:
    box_map = np.zeros((BOX_CHANNELS + 4, *GRID.head_shape), dtype=np.float32)
    box_map[BOX_CHANNELS + cls_at_peak] = 5.0
    return box_map


def test_features_come_from_the_detections_own_returns():
    """Two detections 6 m apart: each cluster holds the returns inside its box (0.3 m to
    spare) nearest to it; a detection with none keeps no features."""
    sensor = (1.0, 0.0)
    # A 0.6 m wide face 10 m ahead (7 returns, 1.0-1.6 m high); a walker-sized one 6 m to its left.
    face = np.array([[11.0, -0.3 + 0.1 * k, 1.0 + 0.1 * k] for k in range(7)])
    walker = np.array([[11.0, 6.0, 1.5], [11.0, 6.2, 1.7], [11.1, 6.1, 0.2]])  # the last one is ground
    boxes = np.array([[11.5, 0.0, 0.0, 1.8, 0.6, 0.9, 0.0], [11.2, 6.1, 0.0, 0.5, 0.5, 0.8, 2.0],
                      [30.0, -10.0, 0.0, 4.6, 1.9, 0.5, 0.0]])
    feats, valid = cluster_class.cluster_features(np.vstack([face, walker]), sensor, boxes, _head_map(0))
    assert valid.tolist() == [True, True, False]
    names = cluster_class.FEATURES
    f = dict(zip(names, feats[0]))
    assert f["log2(1 + returns) / 5"] == pytest.approx(math.log2(8) / 5)
    assert f["range of the returns' centroid [m] / 60"] == pytest.approx(10.0 / 60)
    assert f["highest return [m] / 2"] == pytest.approx(0.8)
    assert f["extent across it [m]"] == pytest.approx(0.6, abs=1e-6)
    assert f["extent along the line of sight [m]"] == pytest.approx(0.0, abs=1e-9)
    assert f["box centre behind the centroid, along the line of sight [m]"] == pytest.approx(0.5)
    assert f["CNN P(car)"] > 0.98
    assert dict(zip(names, feats[1]))["log2(1 + returns) / 5"] == pytest.approx(math.log2(3) / 5)
    assert not feats[2].any()


def test_reclass_replaces_the_class_where_a_cluster_says_otherwise():
    x, y = _toy()
    ensemble = cluster_class.TreeEnsemble.from_sklearn(cluster_class.fit(x, y, seed=0, iterations=5))
    face = np.array([[11.0, -0.3 + 0.1 * k, 1.0 + 0.1 * k] for k in range(7)])
    boxes = np.array([[11.5, 0.0, 0.0, 1.8, 0.6, 0.9, 0.0], [30.0, -10.0, 0.0, 4.6, 1.9, 0.5, 1.0]])
    feats, _ = cluster_class.cluster_features(face, (1.0, 0.0), boxes, _head_map(0))
    wanted = int(ensemble.logits(feats[:1]).argmax())
    # An offset large enough makes any class win; the detection without returns keeps its class.
    offsets = np.zeros(4)
    offsets[3] = 100.0
    out = cluster_class.reclass(boxes.copy(), face, (1.0, 0.0), _head_map(0), ensemble, offsets)
    assert out[:, 6].tolist() == [3.0, 1.0]
    out = cluster_class.reclass(boxes.copy(), face, (1.0, 0.0), _head_map(0), ensemble)
    assert out[:, 6].tolist() == [float(wanted), 1.0]


def test_beam_and_shape_features_count_each_beams_returns():
    """A face 10 m ahead met by the level beam (4 returns at the mount's 1 m) and the +3°
    beam (3 at 1 + 10 tan 3° = 1.52 m), and one return 0.9 m beside the box: the per-beam
    counts, the highest beam, the height shares, the level beam's columns and extent and
    the returns around the box follow by hand."""
    sensor = (1.0, 0.0)
    up = 1.0 + 10.0 * math.tan(math.radians(3.0))
    face = np.array([[11.0, y, 1.0] for y in (-0.3, -0.1, 0.1, 0.3)] + [[11.0, y, up] for y in (-0.2, 0.0, 0.2)]
                    + [[11.0, 1.2, 1.0]])
    boxes = np.array([[11.3, 0.0, 0.0, 0.6, 0.6, 0.9, 3.0]])
    feats, valid = cluster_class.cluster_features(face, sensor, boxes, _head_map(3))
    assert valid.tolist() == [True]
    f = dict(zip(cluster_class.FEATURES, feats[0]))
    assert f["log2(1 + returns) / 5"] == pytest.approx(math.log2(8) / 5)  # the one beside the box is not its own
    assert [f[k] for k in cluster_class.FEATURES[21:26]] == pytest.approx(
        [0.0, 0.0, math.log2(5) / 5, math.log2(4) / 5, 0.0])
    assert f["beams with returns"] == 2 and f["highest beam with returns (0: -6 deg ... 4: +6 deg)"] == 3
    assert f["share of returns above 1.2 m"] == pytest.approx(3 / 7) and f["above 1.6 m"] == 0.0
    assert f["level beam's 1-degree columns / 10"] == pytest.approx(0.4)  # at -1.7, -0.6, 0.6, 1.7 deg
    assert f["level beam's extent across the line of sight [m]"] == pytest.approx(0.6, abs=1e-6)
    assert f["box centre across the line of sight from the centroid [m]"] == pytest.approx(0.0, abs=1e-9)
    assert f["log2(1 + own returns up to 1.5 m outside the box) / 5"] == pytest.approx(0.2)
    assert f["major principal spread [m]"] > f["minor principal spread [m]"] == pytest.approx(0.0, abs=1e-9)
