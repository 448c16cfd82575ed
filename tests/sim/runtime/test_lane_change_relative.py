"""`lane_change to_lane_of X lanes N`: N lanes to X's driver's left of the lane X is in when
the change starts (OpenSCENARIO's RelativeTargetLane with a value), lane 0 skipped."""

from __future__ import annotations

import pytest

from addt_dsl.compiler import compile_source
from addt_dsl.diagnostics import render_text
from addt_dsl.runtime.execute import execute
from addt_dsl.specs.behaviors import lanes_over
from addt_dsl.sweep import expand

SOURCE = """scenario relative_lanes {
  duration 6 s
  road r {
    line length 400 m
    lanes right 3 left 1 width 3.5 m
  }
  ego car on r lane -3 at 10 m speed 0 m/s
  agent ref car on r lane -2 at 100 m speed 10 m/s {
    behavior lane_change to -3 duration 1 s
  }
  agent mover car on r lane -1 at 60 m speed 10 m/s {
    at 2 s behavior lane_change to_lane_of ref lanes LANES duration 2 s
  }
}
"""


@pytest.mark.parametrize("lanes,t_end", [(1, -5.25), (2, -1.75), (3, 1.75), (0, -8.75)])
def test_the_lanes_count_from_the_other_actors_lane_when_the_change_starts(lanes, t_end):
    # `ref` has moved from lane -2 to -3 before the change starts: 1 lane to its left is -2
    # (-1 counted from where it started); 3 lanes crosses the reference line into lane 1.
    result = compile_source(SOURCE.replace("LANES", str(lanes)), path="lanes.addt")
    assert result.ok, render_text(result.diagnostics, result.sources)
    track = execute(expand(result.plan).specs[0]).trace.actors["mover"]
    assert track.t[-1] == pytest.approx(t_end, abs=1e-6)


def test_lanes_without_another_actor_is_a_diagnostic():
    result = compile_source(SOURCE.replace("to_lane_of ref lanes LANES", "to -2 lanes 1"), path="lanes.addt")
    assert not result.ok and any(d.code == "E0105" and "to_lane_of" in d.message for d in result.diagnostics)


@pytest.mark.parametrize("lane,count,target", [(-1, 1, 1), (-1, 2, 2), (-2, 1, -1), (-1, -1, -2), (1, 1, -1),
                                               (1, 2, -2), (2, -1, 3), (1, -1, 2)])
def test_lanes_over_counts_as_esmini(lane, count, target):
    # esmini: ref + value * (forward ? 1 : -1); across lane 0: sign(target - ref) * (|target| + 1).
    assert lanes_over(lane, count) == target


def test_lanes_survive_export_and_import_without_the_side_file(tmp_path):
    from addt_dsl.interop.openscenario.importer import import_xosc
    from addt_dsl.interop.xosc_export import export_run
    plan = compile_source(SOURCE.replace("LANES", "2"), path="lanes.addt").plan
    done = export_run(expand(plan).specs[0], tmp_path)
    assert '<RelativeTargetLane value="2" entityRef="ref"' in done.xosc_path.read_text()
    done.sidecar_path.unlink()
    back = import_xosc(done.xosc_path)
    assert back.plan is not None, [str(d) for d in back.diagnostics]
    assert "to_lane_of ref lanes 2\n" in back.text
