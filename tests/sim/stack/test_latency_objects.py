"""The object-count latency suite: synthesised objects load the stack; the recorded latencies
are the model's (median trend exactly with `latency median`; with jitter, draws that repeat
with the run seed and stay inside the measured quantile table)."""

import math
from pathlib import Path

import numpy as np
import pytest

from addt_dsl.compiler import compile_file, compile_source
from addt_dsl.runtime.execute import execute
from addt_dsl.stack.bev import synthetic_objects
from addt_dsl.stack.latency import at, e2e_ms, load_models
from addt_dsl.sweep import expand
from addt_dsl.vehicles import CAR

SUITE = Path(__file__).resolve().parents[3] / "examples" / "suites" / "latency_objects.addt"


def _specs(text: str | None = None) -> dict:
    result = compile_file(SUITE) if text is None else compile_source(text)
    assert result.ok, result.diagnostics
    return {int(s.params["n_objects"]): s for s in expand(result.plan).specs}


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
        assert (o.length, o.width) == (CAR.length_m, CAR.width_m)  # the catalogue car, not a size of its own


@pytest.mark.slow
def test_median_latency_is_the_trend_and_the_budget_verdict_follows_it():
    specs = _specs(SUITE.read_text().replace("synthetic_objects n_objects",
                                             "synthetic_objects n_objects latency median"))
    assert sorted(specs)[0] == 0
    models = load_models()  # the suite runs on the default target
    for n in (0, 40, max(specs)):
        run = execute(specs[n])
        trace = run.trace
        # Perception reports exactly the synthesised objects (the ego drives alone).
        assert np.all(trace.object_count[100:] == n)
        want_s = e2e_ms(at(models, n), 0.01) / 1e3
        assert np.isclose(np.max(trace.latency["e2e"][100:]), want_s, atol=1e-9)
        verdicts = {v.name: v.passed for v in run.verdicts}
        assert verdicts["latency_budget"] == (np.max(trace.latency["e2e"]) < 0.1)
        assert verdicts["no_collision"] and verdicts["stay_in_lane"]


@pytest.mark.slow
def test_jittered_latencies_repeat_with_the_seed_and_stay_in_the_table():
    n = 40
    spec = _specs()[n]
    first, again = execute(spec), execute(spec)
    assert first.digest == again.digest
    models = load_models()
    trace = first.trace
    for node in ("perception", "tracker", "planner"):
        lat = trace.latency[node][100:]
        ratio = lat / models[node].median(n)
        lo, hi = models[node].ratios[0], models[node].ratios[-1]
        assert ratio.min() >= lo - 1e-9 and ratio.max() <= hi + 1e-9, node
        assert len(np.unique(lat)) > 10, node  # drawn per publication, not a constant
    other = _specs(SUITE.read_text().replace("seed 7", "seed 8"))[n]
    assert other.seed != spec.seed
    assert not np.array_equal(execute(other).trace.latency["perception"], trace.latency["perception"])
