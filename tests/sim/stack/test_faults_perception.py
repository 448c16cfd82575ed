"""A lidar yaw shift misplaces detections more the farther away they are."""

from __future__ import annotations

import math

import pytest

from addt_dsl.compiler import compile_file
from addt_dsl.runtime.execute import execute
from addt_dsl.studies import error_table, perception_errors
from addt_dsl.sweep import expand
from tests.conftest import EXAMPLES

pytestmark = pytest.mark.slow


def test_yaw_shift_errors_grow_with_distance_and_heading_error_is_the_shift():
    plan = compile_file(EXAMPLES / "suites" / "shift_yaw.addt").plan
    plan = plan.model_copy(update={"duration_s": 1.0})
    runs = {s.params["yaw_shift"]: s for s in expand(plan).specs if s.repeat_index == 0}
    rows = []
    for shift in (0.0, math.radians(3)):
        rows += [{"shift": shift, **r} for r in perception_errors(execute(runs[shift]).trace)]
    table = error_table(rows, by=["shift"])
    clean, shifted = table.loc[0.0], table.loc[math.radians(3)]
    assert (clean["position_error_m"] < 0.3).all()  # 0.1 m sigma of noise only
    assert shifted["heading_error_deg"].to_numpy() == pytest.approx(3.0)
    errors = shifted["position_error_m"].to_numpy()
    assert (errors[1:] > errors[:-1]).all()  # bands in increasing range
    # A rotation by the shift about the mount: error ≈ range x shift (0.052 m per m).
    far = shifted.loc["60-80 m"]
    assert 0.04 * 60 < far["position_error_m"] < 0.06 * 80
