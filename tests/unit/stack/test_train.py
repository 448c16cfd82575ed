"""Training is reproducible from the seed (same seed and thread count: same weights, bit for bit)."""

import pytest

torch = pytest.importorskip("torch")

from addt_dsl.stack.train import train  # noqa: E402


def _weights(seed):
    model, _ = train(seed=seed, scenes=48, epochs=1, batch=16, threads=1, lr=1e-3, log=lambda *_: None)
    return model.state_dict()


def test_same_seed_same_weights_other_seed_other_weights():
    a, b, c = _weights(3), _weights(3), _weights(4)
    assert all(torch.equal(a[k], b[k]) for k in a)
    assert any(not torch.equal(a[k], c[k]) for k in a)
