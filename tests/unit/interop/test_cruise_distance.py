"""`cruise ... distance`: a speed change over a distance (OpenSCENARIO's dynamicsDimension
distance) compiles with its checks, prints back, and exports as that dimension."""

from __future__ import annotations

from defusedxml import ElementTree as DET

from addt_dsl.compiler import compile_source
from addt_dsl.interop.xosc_export import export_run
from addt_dsl.printer import print_plan, semantic_key
from addt_dsl.sweep import expand

SOURCE = """scenario over_distance {
  duration 6 s
  road r {
    line length 500 m
    lanes right 2
  }
  ego car on r lane -2 at 10 m speed 0 m/s {
    stack bev cruise_speed 0 m/s
  }
  agent a car on r lane -1 at 100 m speed 25 m/s {
    at 1 s behavior cruise speed 15 m/s distance 60 m shape cubic max_decel 8 m/s^2
  }
}
"""


def test_a_change_over_a_distance_prints_back_and_exports_as_a_distance(tmp_path):
    plan = compile_source(SOURCE, "d.addt").plan
    assert plan is not None
    text = print_plan(plan, keep_user_text=False)
    assert "distance 60 m" in text
    assert semantic_key(compile_source(text, "printed.addt").plan) == semantic_key(plan)
    done = export_run(expand(plan).specs[0], tmp_path)
    dyn = DET.parse(done.xosc_path).getroot().find(".//Event[@name='a_cruise']//SpeedActionDynamics")
    assert (dyn.get("dynamicsShape"), dyn.get("dynamicsDimension"), float(dyn.get("value"))) == \
        ("cubic", "distance", 60.0)


def test_a_duration_and_a_distance_together_are_an_error():
    result = compile_source(SOURCE.replace("distance 60 m", "distance 60 m duration 2 s"), "d.addt")
    assert not result.ok
    (d,) = result.diagnostics
    assert d.code == "E0204" and "not both" in d.message and (d.span.line, d.span.col) == (11, 50)  # at its value
