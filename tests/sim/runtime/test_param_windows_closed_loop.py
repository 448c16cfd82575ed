"""An oracle window from a swept parameter changes the verdict, as a hand calculation says.

A scripted ego follows a lead at 10 m/s; the lead brakes at 4 m/s^2 from 5 s on. Until
5 s the gap keeps its initial value g0; after it the lead is 2 (t - 5)^2 m closer
(relative speed 4 (t - 5) m/s), so `gap > g0 - 5 m` breaks at t = 5 + sqrt(5 / 2) =
6.58 s. `always during [0 s, t_end]` therefore holds for t_end = 4 s (margin 5 m) and
6 s (margin 5 - 2 = 3 m at 6 s) and fails for t_end = 8 s, first at 6.58 s."""

import math

import pytest

from addt_dsl.compiler import compile_source
from addt_dsl.runtime.execute import execute
from addt_dsl.runtime.signals import compute_signals
from addt_dsl.sweep import expand

pytestmark = pytest.mark.slow

SOURCE = """
scenario window_sweep {
  duration 8.5 s
  step 10 ms
  param t_end = 4 s
  road r {
    line length 600 m
  }
  ego car on r lane -1 at 20 m speed 10 m/s {
    behavior cruise speed 10 m/s
  }
  agent lead car on r lane -1 at 50 m speed 10 m/s {
    behavior cruise speed 10 m/s
    at 5 s behavior brake decel 4 m/s^2
  }
  expect {
    keeps_gap: always during [0 s, t_end] gap(ego, lead) > G_MIN
  }
  sweep {
    grid t_end in [4, 6, 8] s
  }
}
"""


def test_a_swept_window_changes_the_verdict():
    probe = compile_source(SOURCE.replace("G_MIN", "0 m"))
    assert probe.plan is not None, [str(d) for d in probe.diagnostics]
    first = execute(expand(probe.plan).specs[0])
    g0 = float(compute_signals(first.trace, {"gap(ego,lead)"})["gap(ego,lead)"][0])  # 30 m less the lengths
    threshold = g0 - 5.0
    result = compile_source(SOURCE.replace("G_MIN", f"{threshold!r} m"))
    assert result.plan is not None, [str(d) for d in result.diagnostics]
    runs = [execute(spec) for spec in expand(result.plan).specs]
    assert [r.params["t_end"] for r in runs] == [4.0, 6.0, 8.0]
    assert all(r.status == "ok" for r in runs), [r.error for r in runs]
    verdicts = [r.verdicts[0] for r in runs]
    assert [v.passed for v in verdicts] == [True, True, False]
    assert verdicts[0].robustness == pytest.approx(5.0, abs=0.02)
    assert verdicts[1].robustness == pytest.approx(3.0, abs=0.05)
    assert verdicts[2].first_violation_s == pytest.approx(5.0 + math.sqrt(2.5), abs=0.03)


def test_export_and_import_keep_the_parameter_window(tmp_path):
    """OpenSCENARIO has no oracles: the export's side file carries the window over t_end
    with the run's value of t_end, and the import gives back the same oracle and verdict."""
    from addt_dsl.interop.openscenario.importer import import_xosc
    from addt_dsl.interop.xosc_export import export_run
    from tests.unit.interop.roundtrip_kit import round_trip

    plan = compile_source(SOURCE.replace("G_MIN", "20 m")).plan
    spec = expand(plan).specs[2]  # t_end = 8 s: fails
    got = round_trip(spec, tmp_path)
    assert got.verdicts_before == got.verdicts_after == {"keeps_gap": False}
    done = export_run(spec, tmp_path / "again", "scenario")
    text = import_xosc(done.xosc_path).text
    assert "param t_end = 8 s" in text and "keeps_gap: always during [0 s, t_end] gap(ego, lead) > 20 m" in text
