"""The trace digest is what replay checks compare: every recorded signal must reach it."""

from __future__ import annotations

import numpy as np

from addt_dsl.runtime.trace import Trace


def _trace(objects: np.ndarray | None, status: str = "ok") -> Trace:
    time = np.arange(4) * 0.01
    return Trace(0.01, time, {}, {"e2e": np.full(4, 0.05)}, [], {"control.accel": np.zeros(4)},
                 objects, status)


def test_the_digest_sees_the_object_count_and_the_status():
    base = _trace(np.array([0.0, 1.0, 1.0, 2.0]))
    assert base.digest() == _trace(np.array([0.0, 1.0, 1.0, 2.0])).digest()
    assert base.digest() != _trace(np.array([0.0, 1.0, 2.0, 2.0])).digest()  # one sample differs
    assert base.digest() != _trace(np.array([0.0, 1.0, 1.0, 2.0]), status="detected").digest()
    assert _trace(None).digest() != base.digest()


def test_the_digest_sees_the_step():
    a = _trace(None)
    b = Trace(0.02, np.arange(4) * 0.02, {}, dict(a.latency), [], dict(a.outputs), None, "ok")
    assert a.digest() != b.digest()
