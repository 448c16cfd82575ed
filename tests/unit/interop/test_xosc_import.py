"""`addtc import`: the esmini corpus translates (or says why not), hostile XML is a
diagnostic, never a traceback, and nothing is read outside the root directory."""

from __future__ import annotations

import json
import random
import re
import shutil

import pytest

from addt_dsl.cli import main
from addt_dsl.compiler import compile_file, compile_source
from addt_dsl.interop.xosc_export import SIDECAR_FORMAT, export_run
from addt_dsl.interop.xosc_import import import_xosc
from addt_dsl.sweep import expand
from tests.conftest import ROOT

ESMINI = ROOT / "tests" / "data" / "esmini"
SCENARIOS = sorted((ESMINI / "xosc").glob("*.xosc"))
# Files that do not import, and the error that says why (docs/openscenario.md).
NOT_IMPORTED = {
    "HWManeuvers.xosc": "not a scenario (a catalog?)",
    "RoutesAtFabriksgatan.xosc": "not a scenario (a catalog?)",
    "parking_lot.xosc": "no <RoadNetwork><LogicFile>",
}


@pytest.mark.parametrize("path", SCENARIOS, ids=[p.name for p in SCENARIOS])
def test_esmini_scenario_imports_or_says_why(path, tmp_path):
    got = import_xosc(path, root=ESMINI)
    errors = [d for d in got.diagnostics if d.is_error]
    for d in got.diagnostics:
        assert d.code in ("E0802", "W0801", "W0802"), d
        assert d.span is not None and d.span.line >= 1, d
    if path.name in NOT_IMPORTED:
        assert got.text is None and any(NOT_IMPORTED[path.name] in d.message for d in errors), errors
        return
    assert not errors, [str(d.message) for d in errors]
    for name, body in got.side_files.items():
        (tmp_path / name).write_text(body)
    result = compile_source(got.text, "imported.addt", base_dir=tmp_path)
    assert result.ok, [d.message for d in result.diagnostics]
    assert result.plan.ego.name == "ego"


def test_cut_in_translates_positions_speeds_and_triggers():
    got = import_xosc(ESMINI / "xosc" / "cut-in_simple.xosc", root=ESMINI)
    plan = got.plan
    assert plan.duration_s == 10.0
    ego, cutter = plan.ego, plan.agents[0]
    assert (ego.s.value, ego.lane.value, ego.speed.value) == (50.0, -1.0, 20.0)
    # RelativeRoadPosition ds=-20 dt=3.1 from the ego: 30 m, the lane to the left.
    assert cutter.s.value == pytest.approx(30.0) and cutter.lane.value == 1.0
    names = [t.clause.name for t in cutter.triggers]
    assert names == ["lane_change", "brake"]
    # The ego's time headway to the cutter: gap(ego, cutter) > headway * speed(ego).
    text = json.dumps(cutter.triggers[0].condition.model_dump())
    assert "gap(ego,OverTaker)" in text and "speed(ego)" in text and "HeadwayTime_LaneChange" in text
    assert "scenario cut_in_simple {" in got.text


def test_parameters_stay_parameters_with_the_dimension_of_their_use():
    got = import_xosc(ESMINI / "xosc" / "acc-test.xosc", root=ESMINI)
    assert got.text is not None
    params = {p.name: p.dimension for p in got.plan.params}
    assert params and all(d in ("speed", "length", "time", "acceleration", "dimensionless")
                           for d in params.values()), params


def test_missing_catalog_uses_documented_defaults(tmp_path):
    (tmp_path / "r.xodr").write_text((ESMINI / "xodr" / "straight_500m.xodr").read_text())
    (tmp_path / "s.xosc").write_text(SMALL.replace("ENTITY", '<CatalogReference catalogName="VehicleCatalog" '
                                                            'entryName="nowhere"/>'))
    got = import_xosc(tmp_path / "s.xosc")
    assert got.text is not None
    assert any(d.code == "W0802" and "default car" in d.message for d in got.diagnostics)


SMALL = """<?xml version="1.0"?>
<OpenSCENARIO>
  <FileHeader revMajor="1" revMinor="2" date="2024-01-01T00:00:00" description="d" author="a"/>
  <RoadNetwork><LogicFile filepath="r.xodr"/></RoadNetwork>
  <Entities><ScenarioObject name="Ego">ENTITY</ScenarioObject></Entities>
  <Storyboard>
    <Init><Actions><Private entityRef="Ego"><PrivateAction><TeleportAction><Position>
      <LanePosition roadId="1" laneId="-1" s="20" offset="0"/></Position></TeleportAction></PrivateAction>
    </Private></Actions></Init>
    <StopTrigger/>
  </Storyboard>
</OpenSCENARIO>
"""

HOSTILE = {
    "malformed": ("<OpenSCENARIO><FileHeader></OpenSCENARIO>", "E0801"),
    "empty": ("", "E0801"),
    "binary": ("\x00\x01\x02", "E0801"),
    "entity_bomb": ('<?xml version="1.0"?><!DOCTYPE l [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;&a;">'
                    '<!ENTITY c "&b;&b;&b;&b;&b;">]><OpenSCENARIO>&c;</OpenSCENARIO>', "E0801"),
    "external_entity": ('<?xml version="1.0"?><!DOCTYPE x [<!ENTITY e SYSTEM "file:///etc/passwd">]>'
                        '<OpenSCENARIO>&e;</OpenSCENARIO>', "E0801"),
    "external_dtd": ('<?xml version="1.0"?><!DOCTYPE x SYSTEM "http://example.invalid/x.dtd"><OpenSCENARIO/>',
                     "E0801"),
    "wrong_root": ("<OpenDRIVE/>", "E0802"),
    "catalog": ('<OpenSCENARIO><FileHeader revMajor="1" revMinor="2"/><Catalog name="c"/></OpenSCENARIO>', "E0802"),
    "road_outside_root": (SMALL.replace("r.xodr", "../../etc/passwd.xodr").replace("ENTITY", ""), "E0402"),
    "road_absolute": (SMALL.replace("r.xodr", "/etc/hosts").replace("ENTITY", ""), "E0402"),
    "road_missing": (SMALL.replace("r.xodr", "missing.xodr").replace("ENTITY", ""), "E0401"),
    "road_url": (SMALL.replace("r.xodr", "http://example.invalid/r.xodr").replace("ENTITY", ""), "E0401"),
    "unknown_parameter": (SMALL.replace('s="20"', 's="$nope"').replace("ENTITY", ""), "E0802"),
    "bad_number": (SMALL.replace('s="20"', 's="twenty"').replace("ENTITY", ""), "E0802"),
    "bad_expression": (SMALL.replace('s="20"', 's="${__import__(1)}"').replace("ENTITY", ""), "E0802"),
    "huge_power": (SMALL.replace('s="20"', 's="${9 ** 99999}"').replace("ENTITY", ""), "E0802"),
    "no_road_id": (SMALL.replace('roadId="1" ', 'roadId="77" ').replace("ENTITY", ""), "E0802"),
    "self_reference": (SMALL.replace("<RoadNetwork>", '<ParameterDeclarations><ParameterDeclaration name="p" '
                                     'parameterType="double" value="$p"/></ParameterDeclarations><RoadNetwork>')
                       .replace('s="20"', 's="$p"').replace("ENTITY", ""), "E0802"),
}


@pytest.mark.parametrize("name", sorted(HOSTILE))
def test_hostile_input_is_a_diagnostic(name, tmp_path):
    text, code = HOSTILE[name]
    scen = tmp_path / "in" / "s.xosc"
    scen.parent.mkdir()
    (scen.parent / "r.xodr").write_text((ESMINI / "xodr" / "straight_500m.xodr").read_text())
    scen.write_bytes(text.encode("latin-1", errors="replace"))
    got = import_xosc(scen)
    assert got.text is None
    assert code in {d.code for d in got.diagnostics}, [(d.code, d.message) for d in got.diagnostics]
    assert all(d.span is None or d.span.line >= 1 for d in got.diagnostics)


def test_cli_import_writes_a_file_that_compiles(tmp_path, capsys):
    out = tmp_path / "out" / "cut.addt"
    code = main(["import", str(ESMINI / "xosc" / "cut-in_simple.xosc"), "--root", str(ESMINI), "-o", str(out)])
    assert code == 0
    assert out.is_file() and (out.parent / "straight_500m.xodr").is_file()
    assert main(["check", str(out)]) == 0
    code = main(["import", str(tmp_path / "nope.xosc")])
    err = capsys.readouterr().err
    assert code == 2 and "E0401" in err and "Traceback" not in err


def test_cli_import_refuses_files_outside_the_scenario_directory_by_default(capsys):
    code = main(["import", str(ESMINI / "xosc" / "cut-in_simple.xosc")])
    err = capsys.readouterr().err
    assert code == 2 and "E0402" in err  # the map is ../xodr/: outside unless --root allows it


VALUES = ["", "-1", "1e308", "nan", "inf", "$x", "${1/0}", "abc", "0", "-5", "999999", "1.5", "${(}", "$"]


@pytest.mark.parametrize("seed", range(4))
def test_mutated_esmini_files_never_raise(seed, tmp_path):
    """Attribute values of real files replaced by hostile ones: diagnostics, never an exception."""
    rng = random.Random(seed)
    shutil.copytree(ESMINI, tmp_path / "e")
    scenarios = [p for p in SCENARIOS if p.name not in NOT_IMPORTED]
    for _ in range(40):
        text = rng.choice(scenarios).read_text()
        for _ in range(rng.randint(1, 4)):
            spans = [m.span(2) for m in re.finditer(r'(\w+)="([^"]*)"', text)]
            a, b = rng.choice(spans)
            text = text[:a] + rng.choice(VALUES) + text[b:]
        path = tmp_path / "e" / "xosc" / "mutated.xosc"
        path.write_text(text)
        got = import_xosc(path, root=tmp_path / "e")
        assert got.text is not None or any(d.is_error for d in got.diagnostics)


@pytest.mark.parametrize("damage", ["not json", '{"format": "other"}', "[1, 2]",
                                    "FORMAT_OK, \"faults\": [{\"kind\": 3}]}",
                                    "FORMAT_OK, \"actors\": {\"ego\": {\"vehicle\": \"tank\"}}}",
                                    "FORMAT_OK, \"behaviors\": {\"lead_cruise\": {\"clause\": 5}}}",
                                    "FORMAT_OK, \"params\": {\"x\": \"y\"}}"])
def test_damaged_side_file_is_a_diagnostic(damage, tmp_path):
    spec = expand(compile_file(ROOT / "examples" / "lead_brake.addt").plan).specs[0]
    done = export_run(spec, tmp_path)
    done.sidecar_path.write_text(damage.replace("FORMAT_OK", '{"format": "%s"' % SIDECAR_FORMAT))
    got = import_xosc(done.xosc_path)
    assert got.text is None
    assert any(d.code == "E0802" and "side file" in d.message for d in got.diagnostics), got.diagnostics
