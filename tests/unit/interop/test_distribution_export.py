"""`addtc export FILE --sweep`: the template and a ParameterValueDistribution of the sweep,
both valid for the ASAM OpenSCENARIO checker, and an import of them gives back the runs."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import pytest

from addt_dsl.cli import main
from addt_dsl.compiler import compile_file, compile_source
from addt_dsl.expr import eval_param_expr
from addt_dsl.interop.openscenario.distribution_export import export_sweep, varied_params
from addt_dsl.interop.openscenario.importer import import_xosc
from addt_dsl.plan import SweepPlan
from addt_dsl.sweep import expand
from tests.conftest import ROOT
from tests.unit.interop.asam_qc import problems

SWEPT = [p for p in sorted((ROOT / "examples").glob("*.addt")) + sorted((ROOT / "examples" / "suites").glob("*.addt"))
         if "sweep" in p.read_text()]


def run_values(plan, names):
    """The runs' values of the varied parameters, as a sorted list (the order of a product
    is the player's)."""
    return sorted(tuple(s.params[n] for n in names) for s in expand(plan).specs)


@pytest.mark.slow  # about 7 s: ~50 exports and imports
def test_every_example_with_a_sweep_comes_back_with_the_same_runs(tmp_path):
    checked = 0
    for path in SWEPT:
        got = compile_file(str(path), root=ROOT / "examples")  # suites may import ../maps
        assert got.ok, path
        plan = got.plan
        if plan.sweep == SweepPlan():
            continue
        done = export_sweep(plan, tmp_path / path.stem, path.stem)
        back = import_xosc(done.distribution_path)
        assert back.plan is not None, (path, [d.message for d in back.diagnostics if d.is_error])
        names = varied_params(plan)
        assert run_values(back.plan, names) == run_values(plan, names), path
        checked += 1
    assert checked >= 40  # examples/ and examples/suites/ have about 50 sweeps


@pytest.mark.parametrize("name, form", [("following", "deterministic"),
                                        pytest.param("suites/state_flip_overtake_copy", "value sets",
                                                     marks=pytest.mark.torch)])  # its stack is learned
def test_both_files_pass_the_asam_checker(tmp_path, name, form, capsys):
    src = ROOT / "examples" / f"{name}.addt"
    assert main(["export", str(src), "--sweep", "--to", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert f"run(s), {form})" in out and "note: " in out
    stem = src.stem
    for f in (tmp_path / f"{stem}.variation.xosc", tmp_path / f"{stem}.xosc"):
        assert problems(f, "qc_openscenario") == []
    doc = ET.parse(tmp_path / f"{stem}.variation.xosc").getroot()
    assert doc.find("ParameterValueDistribution/ScenarioFile").get("filepath") == f"{stem}.xosc"


def test_the_checker_sees_a_broken_distribution(tmp_path):
    # The checker is not vacuous: a DistributionRange without its stepWidth is a schema error.
    plan = compile_file(str(ROOT / "examples" / "following.addt")).plan
    done = export_sweep(plan, tmp_path, "following")
    text = done.distribution_path.read_text().replace(
        "<DistributionSet>", '<DistributionRange><Range lowerLimit="1" upperLimit="2"/></DistributionRange><X>', 1)
    text = text.replace("</DistributionSet>", "</X>", 1)
    bad = tmp_path / "bad.xosc"
    bad.write_text(text)
    assert problems(bad, "qc_openscenario") != []


def test_a_grid_is_deterministic_and_a_sampler_is_its_value_sets(tmp_path):
    src = """scenario s {
  duration 5 s
  road r { line length 500 m }
  param gap = 30 m in [10 m, 60 m]
  param lead_speed = 15 m/s in [5 m/s, 25 m/s]
  ego car on r lane -1 at 10 m speed 15 m/s
  agent lead car on r lane -1 at 10 m + gap speed lead_speed
  sweep {
    %s
  }
}"""
    grid = compile_source(src % "grid gap in [20, 30] m\n    cases lead_speed in [10, 12, 14] m/s").plan
    done = export_sweep(grid, tmp_path / "g", "s")
    doc = ET.parse(done.distribution_path).getroot()
    assert done.form == "deterministic" and done.runs == 6
    assert [e.get("value") for e in doc.iter("Element")] == ["20.0", "30.0"]
    assert len(list(doc.iter("ParameterValueSet"))) == 3
    lhs = compile_source(src % "lhs 7 seed 3").plan
    done = export_sweep(lhs, tmp_path / "l", "s")
    assert done.form == "value sets" and "a lhs sampler" in done.note and done.runs == 7
    sets = list(ET.parse(done.distribution_path).getroot().iter("ParameterValueSet"))
    drawn = sorted((s.params["gap"], s.params["lead_speed"]) for s in expand(lhs).specs)
    written = sorted(tuple(float(a.get("value")) for a in s) for s in sets)
    assert written == drawn  # the exact floats (repr)


def test_the_template_starts_read_the_parameters_as_another_player_would(tmp_path):
    # following.addt: `agent lead ... ahead of ego gap` starts at 20 m + gap with lead_speed.
    plan = compile_file(str(ROOT / "examples" / "following.addt")).plan
    done = export_sweep(plan, tmp_path, "following")
    assert "lead: LanePosition s=${(20.0 + $gap)}" in done.referenced
    assert "lead: AbsoluteTargetSpeed value=$lead_speed" in done.referenced
    assert problems(done.template.xosc_path, "qc_openscenario") == []
    # Without the side file (as another tool has the two files), the distribution still
    # varies the lead's start and speed: the import keeps ${...} over varied parameters.
    done.template.sidecar_path.unlink()
    back = import_xosc(done.distribution_path)
    assert back.plan is not None, [d.message for d in back.diagnostics if d.is_error]
    starts = sorted((eval_param_expr(back.plan.agents[0].s, s.params), eval_param_expr(back.plan.agents[0].speed,
                                                                                      s.params))
                    for s in expand(back.plan).specs)
    want = sorted((20.0 + s.params["gap"], s.params["lead_speed"]) for s in expand(plan).specs)
    assert starts == want and len(want) == 9
