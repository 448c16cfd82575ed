"""The GIF marks a violated hard oracle VIOLATED with a red frame, a violated `warn`
oracle WARNING in amber without one, and nothing before the violation time."""

import numpy as np
import pytest
from tests.unit.runtime.runner_testkit import plan_of, scenario

from addt_dsl.reporting.animation import _AMBER, _RED, TopDownRenderer
from addt_dsl.runtime.execute import execute
from addt_dsl.sweep import expand

PLAN = plan_of(scenario([0], duration="0.3 s"))


@pytest.fixture(scope="module")
def trace():
    return execute(expand(PLAN).specs[0], keep_trace=True).trace


def _frame(trace, violations, k=-1):
    renderer = TopDownRenderer(PLAN)
    return renderer.frame(trace, len(trace.time) - 1 if k == -1 else k, violations, "run")


def _has(img, colour_bgr, region) -> bool:
    return bool((np.abs(img[region].astype(int) - np.array(colour_bgr)).sum(axis=-1) < 30).any())


def test_hard_violation_red_frame(trace):
    img = _frame(trace, [("moving", 0.1, -1.0, "hard")])
    assert _has(img, _RED, np.s_[100:200, 0:4])  # the red border
    assert not _has(img, _AMBER, np.s_[18:32, :])


def test_warning_amber_label_no_red_frame(trace):
    img = _frame(trace, [("comfy", 0.1, -1.0, "warn")])
    assert not _has(img, _RED, np.s_[100:200, 0:4])
    assert _has(img, _AMBER, np.s_[18:32, :])  # the WARNING line


def test_nothing_marked_before_the_violation(trace):
    img = _frame(trace, [("moving", 0.25, -1.0, "hard")], k=0)
    assert not _has(img, _RED, np.s_[100:200, 0:4])
