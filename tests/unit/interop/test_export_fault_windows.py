"""`addtc export` of a run whose fault window a condition opens: OpenSCENARIO has no fault
schedule, so the fault is listed as carried and kept in the side file, start included;
`addtc import` of the export brings it back as the same `when ... for W` fault."""

from __future__ import annotations

import json

from addt_dsl.compiler import compile_source
from addt_dsl.interop.openscenario.importer import import_xosc
from addt_dsl.interop.xosc_export import export_run
from addt_dsl.sweep import expand

SOURCE = """
scenario opened_export {
  duration 8 s
  road r {
    line length 400 m
    lanes right 2
  }
  param near = 25 m in [10 m, 40 m]
  ego car on r lane -1 at 10 m speed 12 m/s {
    stack bev cruise_speed 12 m/s
    sensor lidar rate 10 Hz
  }
  agent lead car on r lane -1 at 60 m speed 6 m/s {
    behavior cruise speed 6 m/s
  }
  faults {
    when rising gap(ego, lead) < near delayed 0.5 s for 2 s drop lidar rate 50 %
  }
}
"""


def test_a_fault_opened_by_a_condition_is_carried_and_read_back(tmp_path):
    spec = expand(compile_source(SOURCE, "opened_export.addt").plan).specs[0]
    done = export_run(spec, tmp_path)
    assert any(line.startswith("fault drop lidar") for line in done.carried)
    (side,) = json.loads(done.sidecar_path.read_text())["faults"]
    assert side["opens"]["edge"] == "rising" and side["end_s"] == 2.0
    got = import_xosc(done.xosc_path)
    assert got.text is not None, [d.message for d in got.diagnostics]
    assert "when rising gap(ego, lead) < 25 m delayed 0.5 s for 2 s drop lidar" in got.text
    (f,) = got.plan.faults
    assert f.opens == spec.faults[0].opens and f.end_s.value == 2.0
