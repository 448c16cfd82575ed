"""Closed loop with learned perception: the overtake example passes and runs are repeatable."""

import numpy as np
import pytest

from addt_dsl.compiler import compile_source
from addt_dsl.runtime.execute import execute
from addt_dsl.sweep import expand

pytestmark = [pytest.mark.slow, pytest.mark.torch]

STACK_LINE = "stack bev cruise_speed 25 m/s"


def _specs(source: str, stack_line: str, duration_s: int | None = None):
    assert STACK_LINE in source
    text = source.replace(STACK_LINE, stack_line)
    if duration_s is not None:
        text = text.replace("duration 30 s", f"duration {duration_s} s")
    result = compile_source(text)
    assert result.ok, result.diagnostics
    return expand(result.plan).specs


def test_overtake_passes_with_learned_perception(learned_overtake_source):
    spec = next(s for s in _specs(learned_overtake_source, "stack bev perception learned cruise_speed 25 m/s")
                if s.params["drop_rate"] == 0.0)
    result = execute(spec)
    assert result.status == "ok", result.error
    assert result.passed, [(v.name, v.robustness) for v in result.verdicts]
    trace = result.trace
    assert trace.object_count.max() >= 1  # the lead was seen by the network, not by ground truth
    ego, lead = trace.actors["ego"], trace.actors["lead"]
    assert ego.s[-1] > lead.s[-1]  # and overtaken


def test_learned_perception_runs_are_deterministic(learned_overtake_source):
    # Frame drops on: the tracker's velocity filter and coasting are exercised too.
    spec = next(s for s in _specs(learned_overtake_source, "stack bev perception learned cruise_speed 25 m/s", 8)
                if s.params["drop_rate"] > 0.0)
    first, second = execute(spec), execute(spec)
    assert first.status == second.status == "ok"
    assert first.digest == second.digest


def test_hil_like_measured_latency_with_learned_perception(learned_overtake_source):
    spec = next(s for s in _specs(learned_overtake_source, "stack bev perception learned latency measured "
                                                    "cruise_speed 25 m/s", 4)
                if s.params["drop_rate"] == 0.0)
    result = execute(spec)
    assert result.status == "ok", result.error
    from addt_dsl.stack.latency import load_models

    perception = result.trace.latency["perception"]
    seen = np.unique(perception[perception > 0.0])
    # Each frame's own measured compute time (no wall-clock bound: machines differ), not the model's.
    assert len(seen) > 10 and np.isfinite(seen).all()
    model = load_models()["perception"]
    modelled = {model.median(n) for n in range(0, 64)}
    assert not set(seen.tolist()) & modelled


def test_learned_perception_digests_do_not_depend_on_worker_count(learned_overtake_source):
    from addt_dsl.runtime.executor import run_local

    specs = _specs(learned_overtake_source, "stack bev perception learned cruise_speed 25 m/s", 5)
    serial = run_local(specs, jobs=1)
    parallel = run_local(specs, jobs=2)
    assert all(r.status == "ok" for r in serial), [r.error for r in serial]
    assert [r.digest for r in serial] == [r.digest for r in parallel]
