"""The calibrated latency model: scale factors meet their targets; the shipped file crosses 100 ms near 40 objects."""

import json
import math

from hypothesis import given, settings
from hypothesis import strategies as st

from addt_dsl.stack.calibrate import TARGETS, pipeline_ms, solve_scales
from addt_dsl.stack.latency import MODEL_PATH, load_models

positive = st.floats(1e-6, 1e-2)


@settings(max_examples=50, deadline=None)
@given(st.tuples(positive, st.floats(1e-8, 1e-5)), st.tuples(positive, st.floats(1e-8, 1e-5)),
       st.tuples(positive, st.floats(1e-8, 1e-5)), st.tuples(st.floats(1e-6, 1e-4), st.just(0.0)))
def test_scale_factors_meet_both_targets(perception, tracker, planner, control):
    measured = {"perception": perception, "tracker": tracker, "planner": planner, "control": control}
    try:
        accel, cpu = solve_scales(measured, TARGETS)
    except ValueError:
        return  # targets unreachable with positive factors: reported, not papered over
    model = {"nodes": {n: {"base_s": b * (accel if n == "perception" else cpu), "per_object_s": p * cpu}
                       for n, (b, p) in measured.items()}}
    assert math.isclose(pipeline_ms(model, 0), TARGETS["pipeline_ms_at_0"], rel_tol=1e-9)
    assert math.isclose(pipeline_ms(model, TARGETS["crossing_objects"]), TARGETS["crossing_ms"], rel_tol=1e-9)


def test_shipped_model_crosses_100_ms_near_40_objects():
    data = json.loads(MODEL_PATH.read_text())
    assert set(data["nodes"]) == {"perception", "tracker", "planner", "control"}
    assert pipeline_ms(data, 35) < 100.0 < pipeline_ms(data, 45)
    models = load_models()
    assert all(m.base_s > 0 and m.per_object_s >= 0 for m in models.values())
    cal = data.get("calibration")
    assert cal and cal["accelerator_scale"] > 0 and cal["cpu_scale"] > 0
    assert set(cal["measured"]) == set(data["nodes"])
