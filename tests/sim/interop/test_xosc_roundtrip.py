"""Round trip: for every example, export -> import -> run gives the verdicts and actor
trajectories of the original run (RMS < 0.1 m); a shrunk counterexample's .xosc replays
the failure. docs/openscenario.md reports the figures (and those without the side file)."""

from __future__ import annotations


import pytest

from addt_dsl.cli import main
from addt_dsl.compiler import compile_file, compile_source
from addt_dsl.interop.openscenario.importer import import_xosc
from addt_dsl.runtime.execute import execute
from addt_dsl.sweep import expand
from tests.conftest import EXAMPLES, ROOT, needs_torch
from tests.sim.kit import solo
from tests.unit.interop.asam_qc import problems
from tests.unit.interop.roundtrip_kit import round_trip

pytestmark = pytest.mark.slow
SCENARIOS = sorted(EXAMPLES.glob("*.addt")) + [ROOT / "tests" / "data" / "interop" / f"{n}.addt"
                                               for n in ("every_behavior", "every_action", "every_light",
                                                                         "every_environment")]


@pytest.mark.parametrize("path", SCENARIOS, ids=[p.stem for p in SCENARIOS])
def test_export_import_run_gives_the_same_run(path, tmp_path):
    if needs_torch(path):
        pytest.importorskip("torch")
    spec = expand(compile_file(path).plan).specs[0]
    got = round_trip(spec, tmp_path, original=solo(spec))  # the batch tests run it alone too
    print(path.stem, got.verdicts_before, {k: round(v, 6) for k, v in got.rms_m.items()})
    assert got.same_verdicts, (got.verdicts_before, got.verdicts_after)
    assert max(got.rms_m.values()) < 0.1, got.rms_m
    assert not [d for d in got.diagnostics if d.startswith("W")], got.diagnostics


def test_shrunk_counterexample_has_a_replayable_xosc(ten_faults_shrunk, tmp_path):
    out, proc = ten_faults_shrunk(1)  # `addtc shrink examples/ten_faults.addt ...`
    assert proc.returncode == 1, proc.stderr
    (addt,) = out.glob("*.addt")
    xosc = addt.with_suffix(".xosc")
    assert xosc.is_file() and (out / f"{addt.stem}.addt.json").is_file()
    assert problems(xosc, "qc_openscenario") == []
    got = import_xosc(xosc)
    back = tmp_path / "back"
    back.mkdir()
    (back / "replay.addt").write_text(got.text)
    for name, body in got.side_files.items():
        (back / name).write_text(body)
    assert main([str(back / "replay.addt"), "--jobs", "1"]) == 1  # the failure replays


RUN_ESMINI = ["cut-in_simple", "acc-test", "alks_cut-in", "straight_500m_pedestrian", "lane_change_simple",
              "highway_merge", "traffic_lights"]


@pytest.mark.parametrize("name", RUN_ESMINI)
def test_imported_esmini_scenario_runs(name, tmp_path):
    esmini = ROOT / "tests" / "data" / "esmini"
    got = import_xosc(esmini / "xosc" / f"{name}.xosc", root=esmini, lenient=True)
    for file, body in got.side_files.items():
        (tmp_path / file).write_text(body)
    (spec,) = expand(compile_source(got.text, f"{name}.addt", base_dir=tmp_path).plan).specs
    result = execute(spec)
    assert result.status == "ok", result.error
    assert [v.name for v in result.verdicts] == ["no_collision"]  # the default oracle
    if name == "cut-in_simple":
        # The file turns the overtaker on lane 1 to drive along +s: it drives that way.
        assert next(a for a in got.plan.agents if a.name == "OverTaker").reverse
