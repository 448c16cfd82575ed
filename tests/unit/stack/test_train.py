"""Training is reproducible from the seed (same seed and thread count: same weights, bit for bit)."""

import pytest

torch = pytest.importorskip("torch")
pytestmark = pytest.mark.torch

from addt_dsl.stack.train import train  # noqa: E402


def _weights(seed):
    model, _ = train(seed=seed, scenes=48, epochs=1, batch=16, threads=1, lr=1e-3, log=lambda *_: None)
    return model.state_dict()


def test_same_seed_same_weights_other_seed_other_weights():
    a, b, c = _weights(3), _weights(3), _weights(4)
    assert all(torch.equal(a[k], b[k]) for k in a)
    assert any(not torch.equal(a[k], c[k]) for k in a)


def test_lidar_vfov_reaches_the_scans_and_the_weights_meta(tmp_path):
    import math

    import numpy as np

    from addt_dsl.stack.synth import generate
    from addt_dsl.stack.train import main

    samples = generate(3, 0, lidars=("360x3",), lidar_settings={"vfov": math.radians(4.0)})
    for s in samples:  # sensor 1 m up: beams at -2, 0, +2 deg
        rel = s.points - np.array([s.sensor_xy[0], s.sensor_xy[1], 1.0])
        elevation = np.degrees(np.arctan2(rel[:, 2], np.hypot(rel[:, 0], rel[:, 1])))
        assert np.abs(elevation).max() < 2.0 + 1e-3 and np.abs(elevation).max() > 1.9
    out = tmp_path / "w.pt"
    assert main(["--scenes", "16", "--epochs", "1", "--batch", "8", "--lidars", "360x3", "--lidar-p", "1",
                 "--lidar-vfov", "4", "--out", str(out)]) == 0
    meta = torch.load(out, weights_only=True)["meta"]
    assert meta["lidar_vfov_deg"] == 4.0 and meta["lidars"] == ["360x3"]
