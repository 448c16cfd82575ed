"""The modelled latency in a closed-loop run with learned perception is what the model predicts."""

import numpy as np
import pytest

from addt_dsl.compiler import compile_source
from addt_dsl.runtime.execute import execute
from addt_dsl.stack.latency import at, e2e_ms, load_models
from addt_dsl.sweep import expand

pytestmark = [pytest.mark.slow, pytest.mark.torch]


def test_trace_e2e_matches_the_median_latency_model(learned_overtake_source):
    text = learned_overtake_source.replace("stack bev cruise_speed 25 m/s",
                                           "stack bev perception learned latency median cruise_speed 25 m/s"
                                           ).replace("duration 30 s", "duration 8 s")
    result = compile_source(text)
    assert result.ok, result.diagnostics
    spec = next(s for s in expand(result.plan).specs if s.params["drop_rate"] == 0.0)
    assert spec.plan.step_s == 0.01
    trace = execute(spec).trace
    models = load_models()
    # After start-up, each sample's e2e derives from a frame whose object count is recorded
    # with it (one frame, one plan, at 10 Hz): compare per object count. The planner plans
    # for confirmed tracks only, so in the frame where an object is first seen it handles
    # fewer than perception detected: its latency is the model's at k <= n objects.
    e2e, objects = trace.latency["e2e"][100:], trace.object_count[100:]
    assert len(np.unique(objects)) >= 1 and objects.max() >= 1
    for n in np.unique(objects):
        nodes = at(models, int(n))
        expected = [e2e_ms({**nodes, "planner": at(models, k)["planner"]}, 0.01) / 1e3 for k in range(int(n) + 1)]
        assert np.isclose(np.median(e2e[objects == n]), expected, atol=1e-9).any()
    # Most frames: every detected object is a confirmed track.
    assert np.isclose(e2e, [e2e_ms(at(models, int(n)), 0.01) / 1e3 for n in objects], atol=1e-9).mean() > 0.8
