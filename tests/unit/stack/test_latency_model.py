"""The calibrated latency model: scale factors meet their targets; the shipped file crosses 100 ms at ~40 objects."""

import json
import math

from hypothesis import assume, given, settings
from hypothesis import strategies as st

from addt_dsl.stack.calibrate import TARGETS, _scaled, e2e_ms, fit, pipeline_ms, solve_scales
from addt_dsl.stack.latency import MODEL_PATH, load_models

STEP = TARGETS["step_s"]
N = TARGETS["crossing_objects"]


@settings(max_examples=30, deadline=None)
@given(st.tuples(st.floats(2e-4, 5e-3), st.floats(1e-7, 2e-5)), st.tuples(st.floats(1e-7, 1e-5), st.floats(1e-7, 1e-5)),
       st.tuples(st.floats(1e-5, 1e-3), st.floats(1e-8, 5e-6)), st.tuples(st.floats(1e-7, 1e-5), st.just(0.0)))
def test_scale_factors_meet_the_targets(perception, tracker, planner, control):
    measured = {"perception": perception, "tracker": tracker, "planner": planner, "control": control}
    try:
        scales = solve_scales(measured, TARGETS)
    except ValueError:  # unreachable with positive factors: reported, not papered over
        scales = None
    assume(scales is not None)
    accel, cpu = scales
    model = _scaled(measured, accel, cpu)
    assert math.isclose(pipeline_ms(model, 0), TARGETS["pipeline_ms_at_0"], rel_tol=1e-9)
    assert e2e_ms(model, N, STEP) >= TARGETS["e2e_crossing_ms"]


def test_e2e_waits_for_the_next_step_at_each_hand_over():
    model = {"nodes": {"perception": {"base_s": 0.0331, "per_object_s": 0.0},
                       "tracker": {"base_s": 0.0001, "per_object_s": 0.0},
                       "planner": {"base_s": 0.0064, "per_object_s": 0.0},
                       "control": {"base_s": 0.0004, "per_object_s": 0.0}}}
    # Objects delivered at 40 ms, tracks at 50 ms; plan out 6.4 ms later; control 0.4 ms.
    assert math.isclose(e2e_ms(model, 0, 0.01), 56.8)


def test_fit_uses_the_zero_object_cost_as_base():
    base, per = fit([(0, 1.0), (10, 2.0), (20, 5.0)])  # super-linear, as association is
    assert base == 1.0 and per > 0


def test_shipped_model_crosses_100_ms_near_40_objects():
    data = json.loads(MODEL_PATH.read_text())
    assert set(data["nodes"]) == {"perception", "tracker", "planner", "control"}
    assert e2e_ms(data, N - 5, STEP) < 100.0 < e2e_ms(data, N + 5, STEP)
    assert all(m.base_s > 0 and m.per_object_s >= 0 for m in load_models().values())
    cal = data["calibration"]
    assert cal["accelerator_scale"] > 0 and cal["cpu_scale"] > 0
    assert set(cal["measured"]) == set(data["nodes"])
