"""shift (sudden, drift) and additive noise on lidar and GNSS frames."""

import math

import numpy as np
import pytest
from tests.unit.runtime.faults.faultkit import lidar_frame, one

from addt_dsl.runtime.sensors import Extrinsics, Frame


class _Sensor:
    name = "lidar"

    def __init__(self):
        self.nominal = Extrinsics()
        self.actual = self.nominal


def test_sudden_shift_moves_the_actual_mount_only_after_the_start():
    kind, events = one("shift", yaw=math.radians(2), x=0.1, start=1.0)
    s = _Sensor()
    kind.before_capture(s, 0.5)
    assert s.actual == s.nominal and not events
    kind.before_capture(s, 1.0)
    assert s.actual.yaw == pytest.approx(math.radians(2)) and s.actual.x == pytest.approx(1.1)
    assert s.nominal.yaw == 0.0  # the stack keeps the calibration
    kind.before_capture(s, 5.0)
    assert len(events) == 1
    d = events[0].detail
    assert d["location"] == "lidar" and d["value"] == {"x": 0.1, "yaw": pytest.approx(math.radians(2))}


def test_drift_ramps_linearly_to_the_full_shift_and_records_start_and_end():
    kind, events = one("shift", yaw=0.1, ramp=4.0, start=2.0)
    s = _Sensor()
    for t, want in ((2.0, 0.0), (3.0, 0.025), (4.0, 0.05), (6.0, 0.1), (9.0, 0.1)):
        kind.before_capture(s, t)
        assert s.actual.yaw == pytest.approx(want)
    assert [e.detail["fraction"] for e in events] == [0.0, 1.0]


def test_lidar_range_noise_moves_points_along_their_rays():
    kind, events = one("noise", range=0.2, seed=5)
    frame = lidar_frame(4000)
    before = frame.data["points"].copy()
    out, _ = kind.on_frame(frame, 0.0)
    after = out.data["points"]
    r0, r1 = np.linalg.norm(before, axis=1), np.linalg.norm(after, axis=1)
    assert np.std(r1 - r0) == pytest.approx(0.2, rel=0.06)
    cos = np.sum(before * after, axis=1) / (r0 * r1)
    assert np.allclose(cos, 1.0)
    assert events[0].detail["value"] == pytest.approx(0.2, rel=0.06)
    assert len(out.data["hit_body"]) == len(after)


def test_lidar_dropout_removes_points_and_their_labels_together():
    kind, events = one("noise", dropout=0.3, seed=6)
    frame = lidar_frame(5000)
    pts, ids = frame.data["points"], frame.data["hit_body"]
    out, _ = kind.on_frame(frame, 0.0)
    kept = len(out.data["points"])
    assert kept == len(out.data["hit_body"])
    assert 0.27 < 1 - kept / 5000 < 0.33
    assert events[0].detail["returns_lost"] == 5000 - kept
    # Every surviving (point, label) pair was a pair in the input.
    lookup = {tuple(p): i for p, i in zip(pts.tolist(), ids.tolist())}
    assert all(lookup[tuple(p)] == i for p, i in zip(out.data["points"].tolist(), out.data["hit_body"].tolist()))


def test_gnss_position_noise():
    kind, events = one("noise", target="gnss", position=2.0, seed=7)
    errs = []
    for _ in range(2000):
        f = Frame("gnss", 0.0, {"x": 10.0, "y": -4.0, "heading": 0.3, "speed": 5.0})
        out, _ = kind.on_frame(f, 0.0)
        errs.append((out.data["x"] - 10.0, out.data["y"] + 4.0))
        assert out.data["heading"] == 0.3
    assert np.std(np.array(errs), axis=0) == pytest.approx([2.0, 2.0], rel=0.08)
    assert events[0].detail["value"] == pytest.approx(math.hypot(*errs[0]))


def test_noise_outside_its_window_leaves_frames_alone():
    kind, events = one("noise", range=1.0, dropout=0.5, start=5.0, end=6.0)
    frame = lidar_frame(100)
    pts = frame.data["points"].copy()
    out, _ = kind.on_frame(frame, 1.0)
    assert (out.data["points"] == pts).all() and not events
