"""drop, delay, skew: which frames, how late, determinism."""

import numpy as np
from tests.unit.runtime.faults.faultkit import lidar_frame, one, schedule
from hypothesis import given, settings
from hypothesis import strategies as st


def _drops(kind, frames=400, period=0.1):
    out = []
    for i in range(frames):
        frame, _ = kind.on_frame(lidar_frame(5, stamp=i * period), i * period)
        out.append(frame is None)
    return np.array(out)


def test_rate_zero_never_drops_rate_one_always():
    assert not _drops(one("drop", rate=0.0)[0]).any()
    assert _drops(one("drop", rate=1.0)[0]).all()


def test_drops_only_inside_the_window():
    kind, events = one("drop", rate=1.0, start=2.0, end=3.0)
    d = _drops(kind, frames=50)
    t = np.arange(50) * 0.1
    assert d[(t >= 2.0) & (t <= 3.0)].all() and not d[(t < 2.0) | (t > 3.0 + 1e-9)].any()
    assert len(events) == d.sum()
    e = events[0].detail
    assert e["kind"] == "drop" and e["location"] == "lidar" and e["value"] == 2.0 and e["dropped"]


def test_drop_rate_is_the_bernoulli_probability():
    d = _drops(one("drop", rate=0.1, seed=3)[0], frames=5000)
    assert 0.085 < d.mean() < 0.115  # 5000 draws: 1 sigma = 0.0042


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), rate=st.floats(0.01, 0.5), burst=st.integers(1, 6))
def test_bursts_lose_whole_runs_of_frames(seed, rate, burst):
    d = _drops(one("drop", rate=rate, burst=burst, seed=seed)[0], frames=300)
    runs, n = [], 0
    for x in d:
        if x:
            n += 1
        elif n:
            runs.append(n)
            n = 0
    # A run is one or more back-to-back events of `burst` frames (the last one may be cut by the end).
    assert all(r % burst == 0 for r in runs)


def test_same_seed_same_drops_and_other_faults_do_not_interfere():
    a = _drops(one("drop", rate=0.3, seed=9)[0])
    b = _drops(one("drop", rate=0.3, seed=9)[0])
    assert (a == b).all()
    sched, _ = schedule({"kind": "drop", "rate": 0.3, "seed": 9},
                        {"kind": "noise", "target": "lidar", "dropout": 0.5, "seed": 4})
    c = []
    for i in range(400):
        frame, t = lidar_frame(5, stamp=i * 0.1), i * 0.1
        for k in sched.for_target("lidar"):
            if frame is not None:
                frame, _ = k.on_frame(frame, t)
        c.append(frame is None)
    assert (np.array(c) == a).all()
    assert (_drops(one("drop", rate=0.3, seed=10)[0]) != a).any()


def test_delay_is_by_plus_uniform_jitter_and_recorded():
    kind, events = one("delay", by=0.05, jitter=0.1, seed=2)
    delays = [kind.on_frame(lidar_frame(3), 0.0)[1] for _ in range(500)]
    assert 0.05 <= min(delays) and max(delays) <= 0.15 and np.std(delays) > 0.02
    assert [e.detail["value"] for e in events] == delays
    kind, _ = one("delay", by=0.2)
    assert {kind.on_frame(lidar_frame(3), 0.0)[1] for _ in range(5)} == {0.2}


def test_skew_changes_the_stamp_not_the_data():
    kind, events = one("skew", by=-0.3)
    frame = lidar_frame(10, stamp=1.0)
    pts = frame.data["points"].copy()
    out, delay = kind.on_frame(frame, 1.0)
    assert out.stamp_s == 0.7 and delay == 0.0 and (out.data["points"] == pts).all()
    assert events[0].detail["value"] == 0.7 and events[0].detail["offset_s"] == -0.3
