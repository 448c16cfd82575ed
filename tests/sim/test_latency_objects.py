"""The object-count latency suite: synthesised objects load the stack; the 100 ms budget
breaks where the latency model says (40 objects, as in the paper)."""

import json
import math
from pathlib import Path

import numpy as np
import pytest

from addt_dsl.compiler import compile_file
from addt_dsl.runtime.execute import execute
from addt_dsl.stack.bev import synthetic_objects
from addt_dsl.stack.calibrate import e2e_ms
from addt_dsl.stack.latency import MODEL_PATH
from addt_dsl.sweep import expand

SUITE = Path(__file__).resolve().parents[2] / "examples" / "suites" / "latency_objects.addt"


def test_synthetic_objects_are_distinct_off_road_and_deterministic():
    pose = (100.0, -5.0, 0.3, 20.0)
    objs = synthetic_objects(120, pose)
    assert objs == synthetic_objects(120, pose)
    assert len({(round(o.x, 6), round(o.y, 6)) for o in objs}) == 120
    c, s = math.cos(0.3), math.sin(0.3)
    for o in objs:  # ego-frame lateral offset at least 12 m; same heading and velocity as the ego
        lateral = -s * (o.x - 100.0) + c * (o.y + 5.0)
        assert abs(lateral) >= 12.0 - 1e-9
        assert (o.heading, o.vx, o.vy) == (0.3, pytest.approx(20 * c), pytest.approx(20 * s))


@pytest.mark.slow
def test_budget_breaks_at_40_objects():
    result = compile_file(SUITE)
    assert result.ok, result.diagnostics
    specs = {int(s.params["n_objects"]): s for s in expand(result.plan).specs}
    assert sorted(specs)[0] == 0 and sorted(specs)[-1] == 80
    model = json.loads(MODEL_PATH.read_text())
    verdicts = {}
    for n in (0, 39, 40, 80):
        run = execute(specs[n])
        trace = run.trace
        # Perception reports exactly the synthesised objects (the ego drives alone).
        assert np.all(trace.object_count[100:] == n)
        assert np.isclose(np.max(trace.latency["e2e"][100:]), e2e_ms(model, n, 0.01) / 1e3, atol=1e-9)
        verdicts[n] = {v.name: v.passed for v in run.verdicts}
    assert [verdicts[n]["latency_budget"] for n in (0, 39, 40, 80)] == [True, True, False, False]
    assert all(verdicts[n]["no_collision"] and verdicts[n]["stay_in_lane"] for n in verdicts)
