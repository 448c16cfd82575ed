"""`addtc import`: the esmini corpus translates (or says why not), hostile XML is a
diagnostic, never a traceback, and nothing is read outside the root directory."""

from __future__ import annotations

import json
import random
import re
import shutil
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from addt_dsl.cli import main
from addt_dsl.compiler import compile_file, compile_source
from addt_dsl.expr import eval_param_expr
from addt_dsl.interop.xosc_export import SIDECAR_FORMAT, export_run
from addt_dsl.interop.openscenario.importer import import_xosc
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
    # Strict (the default): an element that is not translated refuses the file (E0803);
    # lenient: the same elements, each a W0801 at the same line, and the rest imports.
    strict = import_xosc(path, root=ESMINI)
    got = import_xosc(path, root=ESMINI, lenient=True)
    errors = [d for d in got.diagnostics if d.is_error]
    for d in got.diagnostics:
        assert d.code in ("E0802", "W0801", "W0802"), d
        assert d.span is not None and d.span.line >= 1, d
    refused = [(d.span.line, d.message) for d in strict.diagnostics if d.code == "E0803"]
    left_out = [(d.span.line, d.message) for d in got.diagnostics if d.code == "W0801"]
    assert refused == left_out
    assert (strict.plan is None) == bool(refused) or path.name in NOT_IMPORTED
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
    # Its stop trigger: after 10 s, once the cutter's acceleration has come back to 0 (2 s later).
    assert plan.duration_s == 300.0 and plan.end.at_s.value == 10.0 and plan.end.delay_s.value == 2.0
    assert plan.end.edge == "rising" and "accel(OverTaker)" in got.text
    ego, cutter = plan.ego, plan.agents[0]
    assert (ego.s.value, ego.lane.value, ego.speed.value) == (50.0, -1.0, 20.0)
    # RelativeRoadPosition ds=-20 dt=3.1 from the ego: 30 m, the lane to the left.
    assert cutter.s.value == pytest.approx(30.0) and cutter.lane.value == 1.0
    names = [t.clause.name for t in cutter.triggers]
    assert names == ["lane_change", "cruise"]  # the brake to 0 m/s at its rate
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
                                    "FORMAT_OK, \"params\": {\"x\": \"y\"}}",
                                    "FORMAT_OK, \"run_seed\": 1.5}", "FORMAT_OK, \"seed\": true}"])
def test_damaged_side_file_is_a_diagnostic(damage, tmp_path):
    spec = expand(compile_file(ROOT / "examples" / "lead_brake.addt").plan).specs[0]
    done = export_run(spec, tmp_path)
    done.sidecar_path.write_text(damage.replace("FORMAT_OK", '{"format": "%s"' % SIDECAR_FORMAT))
    got = import_xosc(done.xosc_path)
    assert got.text is None
    assert any(d.code == "E0802" and "side file" in d.message for d in got.diagnostics), got.diagnostics


def test_a_side_file_of_another_export_is_refused(tmp_path):
    """Two exports side by side, one side file copied over the other's: importing it
    brought the other scenario's stack, faults, oracles and name into this one, silently."""
    runs = {name: expand(compile_file(ROOT / "examples" / f"{name}.addt").plan).specs[0]
            for name in ("lead_brake", "following")}
    done = {name: export_run(spec, tmp_path / name) for name, spec in runs.items()}
    done["lead_brake"].sidecar_path.write_bytes(done["following"].sidecar_path.read_bytes())
    got = import_xosc(done["lead_brake"].xosc_path)
    assert got.text is None
    (d,) = [d for d in got.diagnostics if d.is_error]
    assert d.code == "E0802" and "written for scenario 'following'" in d.message and "'lead_brake'" in d.message


def _without_sidecar(spec, tmp_path):
    """Export a run and drop its side file: only what the .xosc itself says comes back."""
    done = export_run(spec, tmp_path, "scenario")
    done.sidecar_path.unlink()
    got = import_xosc(done.xosc_path)
    assert got.text is not None, [d.message for d in got.diagnostics]
    return got


def test_actions_come_back_from_the_xosc_alone(tmp_path):
    spec = expand(compile_file(ROOT / "tests" / "data" / "interop" / "every_action.addt").plan).specs[0]
    got = _without_sidecar(spec, tmp_path)
    plan = {a.name: a for a in got.plan.actors()}

    def clause(actor):
        a = plan[actor]
        return (a.behaviors + [t.clause for t in a.triggers])[0]

    def nums(values):
        return [v.value for v in values]

    profile = clause("profiler")
    assert profile.name == "speed_profile"
    assert nums(profile.settings["times"]) == [0.0, 4.0, 8.0] and nums(profile.settings["speeds"]) == [10.0, 14.0, 8.0]
    shaped = clause("shaper")
    assert (shaped.name, shaped.settings["shape"], shaped.settings["duration"].value) == ("cruise", "sinusoidal", 3.0)
    change = plan["shaper"].triggers[0].clause
    assert (change.name, change.settings["to_lane_of"], change.settings["shape"]) == \
        ("lane_change", "profiler", "linear")
    assert "to" not in change.settings
    relative = clause("faster")
    assert relative.name == "cruise" and "1.2 * speed(ego)" in got.text
    gap = clause("keeper")
    assert (gap.name, gap.settings["target"], gap.settings["distance"].value) == ("keep_gap", "ego", 15.0)
    step = plan["walker"].triggers[0]
    assert step.delay_s.value == 0.5 and step.hold_s is None  # the condition delay
    sync = step.clause
    assert sync.name == "synchronize" and sync.settings["master"] == "ego"
    assert (sync.settings["master_at"].value, sync.settings["target_s"].value) == (150.0, 150.0)
    assert sync.settings["target_t"].value == pytest.approx(-5.25)
    traj = clause("drifter")
    assert traj.name == "trajectory"
    assert nums(traj.settings["s"]) == [280.0, 250.0, 220.0] and nums(traj.settings["times"]) == [2.0, 5.0, 8.0]
    assert nums(traj.settings["t"]) == pytest.approx([1.75, 3.0, 1.75])
    env = {c.name: c.settings for c in got.plan.environment}
    assert env["fog"]["visibility"].value == 300.0
    assert env["rain"]["rate"].value == pytest.approx(5e-3 / 3600.0)
    assert env["light"]["sun"].value == pytest.approx(0.5235987755982988)
    # What is approximated says so; nothing else is dropped.
    messages = [d.message for d in got.diagnostics if d.code in ("W0801", "W0802")]
    assert not any("delay" in m for m in messages)  # a condition delay is exact: `delayed 0.5 s`
    assert not any(d.code == "W0801" for d in got.diagnostics), messages


def test_routes_come_back_from_the_xosc_alone(tmp_path):
    spec = expand(compile_file(ROOT / "examples" / "left_turn.addt").plan).specs[0]
    got = _without_sidecar(spec, tmp_path)
    before = {a.name: a for a in spec.plan.actors()}
    for actor in got.plan.actors():
        assert actor.route == before[actor.name].route, actor.name
        # `at S` counts along the route from its entry end (lane 1 of road 0 runs against s).
        after_params = {p.name: p.default for p in got.plan.params}
        assert eval_param_expr(actor.s, after_params) == pytest.approx(
            eval_param_expr(before[actor.name].s, spec.params), abs=1e-9), actor.name


def test_esmini_trajectories_and_synchronisation(tmp_path):
    # A trajectory in Init places the pedestrian at its first vertex and starts it.
    ped = import_xosc(ESMINI / "xosc" / "alks_pedestrian.xosc", root=ESMINI)
    walker = next(a for a in ped.plan.agents if a.vehicle == "pedestrian")
    traj = walker.behaviors[0]
    assert traj.name == "trajectory" and [v.value for v in traj.settings["s"]][:2] == [110.0, 110.0]
    assert walker.s.value == 110.0
    # Points relative to an entity in an event after time 0: esmini places them from where
    # the entity is when the action starts, which the language cannot say (refused).
    strict = import_xosc(ESMINI / "xosc" / "trajectory-test.xosc", root=ESMINI)
    assert sum("a trajectory relative to 'Target' in an event" in d.message
               for d in strict.diagnostics if d.code == "E0803") == 3
    # The same file with the points absolute (where they were from the Target's start, s =
    # 10 m of lane -1): a timed polyline started by a held condition (delay 0.2 s).
    text = (ESMINI / "xosc" / "trajectory-test.xosc").read_text()
    text = re.sub(r'<RelativeLanePosition dLane="(-?\d)" ds="(\d+)" entityRef="Target" offset="([-.\d]+)"/>',
                  lambda m: f'<LanePosition roadId="1" laneId="{-1 + int(m[1]) + (int(m[1]) > 0)}" '
                            f's="{10 + int(m[2])}" offset="{m[3]}"/>', text)
    text = text.replace('<RelativeRoadPosition dt="0" ds="0" entityRef="Target"/>',
                        '<LanePosition roadId="1" laneId="-1" s="10" offset="0"/>')
    shutil.copytree(ESMINI, tmp_path / "esmini")
    (tmp_path / "esmini" / "xosc" / "absolute.xosc").write_text(text)
    got = import_xosc(tmp_path / "esmini" / "xosc" / "absolute.xosc", root=tmp_path / "esmini", lenient=True)
    step = next(t for a in got.plan.agents for t in a.triggers if t.group is not None)
    first, clothoid = step.group.steps
    assert [v.value for v in first.clause.settings["times"]] == [0.0, 2.0, 4.0, 6.0]
    assert step.delay_s.value == pytest.approx(0.2) and step.hold_s is None
    # The clothoid starts when the polyline ends (its last vertex time), sampled and said so.
    assert step.group.mode == "sequence" and clothoid.after_s.value == 6.0 and "x" in clothoid.clause.settings
    assert {d.label for d in got.diagnostics if "sampled as a polyline" in d.message} == {"<Clothoid>", "<Nurbs>"}


def test_a_live_target_without_an_openscenario_form_travels_as_a_controller(tmp_path):
    source = (ROOT / "tests" / "data" / "interop" / "every_action.addt").read_text().replace(
        "behavior cruise speed 1.2 * speed(ego) accel 3 m/s^2",
        "behavior cruise speed 2 * speed(ego) - 1 m/s accel 3 m/s^2")
    plan = compile_source(source, "live.addt").plan
    spec = expand(plan).specs[0]
    got = _without_sidecar(spec, tmp_path)
    assert "behavior cruise speed 2 * speed(ego) - 1 m/s" in got.text
    faster = next(a for a in got.plan.agents if a.name == "faster")
    original = next(a for a in plan.agents if a.name == "faster")
    assert faster.behaviors[0].settings["speed"] == original.behaviors[0].settings["speed"]


FOLLOWER_EVENT = """
            <ManeuverGroup maximumExecutionCount="1" name="FollowerGroup">
               <Actors selectTriggeringEntities="false">
                  <EntityRef entityRef="Follower"/>
               </Actors>
               <Maneuver name="FollowerManeuver">
                  <Event name="FollowerBrake" priority="overwrite">
                     <Action name="FollowerBrakeAction">
                        <PrivateAction>
                           <LongitudinalAction>
                              <SpeedAction>
                                 <SpeedActionDynamics dynamicsShape="linear" value="-4" dynamicsDimension="rate"/>
                                 <SpeedActionTarget>
                                    <AbsoluteTargetSpeed value="0"/>
                                 </SpeedActionTarget>
                              </SpeedAction>
                           </LongitudinalAction>
                        </PrivateAction>
                     </Action>
                     <StartTrigger>
                        <ConditionGroup>
                           <Condition name="AfterBrake" delay="0" conditionEdge="rising">
                              <ByValueCondition>
                                 <StoryboardElementStateCondition storyboardElementType="event"
                                    storyboardElementRef="BrakeEvent" state="%s"/>
                              </ByValueCondition>
                           </Condition>
                        </ConditionGroup>
                     </StartTrigger>
                  </Event>
               </Maneuver>
            </ManeuverGroup>
"""


@pytest.mark.parametrize("state,fn", [("endTransition", "ended"), ("startTransition", "started")])
def test_another_actors_event_state_becomes_a_named_step(state, fn, tmp_path):
    """StoryboardElementStateCondition on another actor's translated event: that event's
    step is named and this one starts on `ended(...)`/`started(...)` of it."""
    text = (ESMINI / "xosc" / "cut-in_simple.xosc").read_text()
    text = text.replace('      <ScenarioObject name="OverTaker">', '      <ScenarioObject name="Follower">\n'
                        '         <CatalogReference catalogName="VehicleCatalog" entryName="$TargetVehicle"/>\n'
                        '      </ScenarioObject>\n      <ScenarioObject name="OverTaker">', 1)
    init = text[text.index('            <Private entityRef="OverTaker">'):text.index("         </Actions>")]
    text = text.replace("         </Actions>", init.replace('"OverTaker"', '"Follower"')
                        .replace('ds="-20"', 'ds="-40"') + "         </Actions>", 1)
    text = text.replace("            </ManeuverGroup>\n", "            </ManeuverGroup>\n" + FOLLOWER_EVENT % state, 1)
    shutil.copytree(ESMINI, tmp_path / "esmini")
    path = tmp_path / "esmini" / "xosc" / "two.xosc"
    path.write_text(text)
    got = import_xosc(path, root=tmp_path / "esmini")
    assert got.text is not None, [d.message for d in got.diagnostics]
    assert "BrakeEvent: when " in got.text and f"when {fn}(OverTaker.BrakeEvent) then behavior cruise" in got.text
    for name, body in got.side_files.items():
        (tmp_path / name).write_text(body)
    result = compile_source(got.text, "imported.addt", base_dir=tmp_path)
    assert result.ok, [d.message for d in result.diagnostics]


def test_esmini_traffic_lights_translate(tmp_path):
    """esmini's traffic_lights.xosc sets signals directly (no controllers): each signal gets
    a controller of its own, Init states are steps at time 0, state actions light steps and
    TrafficSignalConditions `light(C) == S` (its delays `for D`, said with their lines)."""
    got = import_xosc(ESMINI / "xosc" / "traffic_lights.xosc", root=ESMINI)
    assert got.text is not None
    plan = got.plan
    assert [(c.name, c.signals) for c in plan.controllers] == [("signal_1", ["1"]), ("signal_2", ["2"]),
                                                              ("signal_3", ["3"])]
    steps = [(tr.clause.name, tr.clause.settings["state"]) for tr in plan.light_steps]
    assert steps[:3] == [("signal_1", "green"), ("signal_2", "red"), ("signal_3", "red")]
    assert ("signal_1", "yellow") in steps and ("signal_1", "red") in steps
    assert "when light(signal_1) == yellow delayed 3 s then light signal_1 state red" in got.text
    assert "when light(signal_3) == green delayed 0.5 s then behavior" in got.text
    assert not any("TrafficSignal" in d.message or "signals" in d.message
                   for d in got.diagnostics if d.code == "W0801"), [d.message for d in got.diagnostics]
    assert not any("delay" in d.message for d in got.diagnostics)  # delays translate exactly
    # The esmini file's actors follow their actions, not the lights.
    assert all(a.ignore_lights for a in plan.agents) and not plan.ego.ignore_lights


LIGHTS = """<?xml version="1.0"?>
<OpenSCENARIO>
  <FileHeader revMajor="1" revMinor="2" date="2024-01-01T00:00:00" description="d" author="a"/>
  <RoadNetwork><LogicFile filepath="m.xodr"/>
    <TrafficSignals>
      <TrafficSignalController name="west">
        PHASES
      </TrafficSignalController>
    </TrafficSignals>
  </RoadNetwork>
  <Entities>
    <ScenarioObject name="Ego"><Vehicle name="c" vehicleCategory="car"><BoundingBox><Center x="0" y="0" z="0.7"/>
      <Dimensions width="2" length="4.5" height="1.4"/></BoundingBox></Vehicle></ScenarioObject>
    <ScenarioObject name="car"><Vehicle name="c" vehicleCategory="car"><BoundingBox><Center x="0" y="0" z="0.7"/>
      <Dimensions width="2" length="4.5" height="1.4"/></BoundingBox></Vehicle></ScenarioObject>
  </Entities>
  <Storyboard>
    <Init><Actions>
      <Private entityRef="Ego"><PrivateAction><TeleportAction><Position>
        <LanePosition roadId="3" laneId="-1" s="10" offset="0"/></Position></TeleportAction></PrivateAction></Private>
      <Private entityRef="car"><PrivateAction><TeleportAction><Position>
        <LanePosition roadId="3" laneId="-1" s="40" offset="0"/></Position></TeleportAction></PrivateAction></Private>
    </Actions></Init>
    <Story name="s"><Act name="a">
      <ManeuverGroup name="lights" maximumExecutionCount="1"><Actors selectTriggeringEntities="false"/>
        <Maneuver name="m">
          <Event name="to_red" priority="parallel">
            <Action name="a1"><GlobalAction><InfrastructureAction><TrafficSignalAction>
              <TrafficSignalControllerAction trafficSignalControllerRef="CTL" phase="stop"/>
            </TrafficSignalAction></InfrastructureAction></GlobalAction></Action>
            <StartTrigger><ConditionGroup><Condition name="t" delay="0" conditionEdge="none"><ByValueCondition>
              <SimulationTimeCondition value="4" rule="greaterThan"/></ByValueCondition></Condition></ConditionGroup>
            </StartTrigger>
          </Event>
        </Maneuver>
      </ManeuverGroup>
      <ManeuverGroup name="g" maximumExecutionCount="1"><Actors selectTriggeringEntities="false">
        <EntityRef entityRef="car"/></Actors>
        <Maneuver name="m2">
          <Event name="go" priority="parallel">
            <Action name="a2"><PrivateAction><LongitudinalAction><SpeedAction>
              <SpeedActionDynamics dynamicsShape="step" value="0" dynamicsDimension="time"/>
              <SpeedActionTarget><AbsoluteTargetSpeed value="5"/></SpeedActionTarget></SpeedAction>
            </LongitudinalAction></PrivateAction></Action>
            <StartTrigger><ConditionGroup><Condition name="c" delay="0" conditionEdge="none"><ByValueCondition>
              <TrafficSignalControllerCondition trafficSignalControllerRef="west" phase="go"/>
            </ByValueCondition></Condition></ConditionGroup></StartTrigger>
          </Event>
        </Maneuver>
      </ManeuverGroup>
      <StartTrigger><ConditionGroup><Condition name="s" delay="0" conditionEdge="none"><ByValueCondition>
        <SimulationTimeCondition value="0" rule="greaterThan"/></ByValueCondition></Condition></ConditionGroup>
      </StartTrigger>
    </Act></Story>
    <StopTrigger><ConditionGroup><Condition name="e" delay="0" conditionEdge="rising"><ByValueCondition>
      <SimulationTimeCondition value="20" rule="greaterThan"/></ByValueCondition></Condition></ConditionGroup>
    </StopTrigger>
  </Storyboard>
</OpenSCENARIO>
"""


def _phase(name, duration, state):
    return (f'<Phase name="{name}" duration="{duration}"><TrafficSignalState trafficSignalId="1" state="{state}"/>'
            f'<TrafficSignalState trafficSignalId="2" state="{"on;off" if state.startswith("on") else "off;on"}"/>'
            "</Phase>")


def _lights_file(tmp_path, phases, ref="west"):
    (tmp_path / "m.xodr").write_text((ESMINI / "xodr" / "fabriksgatan_traffic_lights.xodr").read_text())
    (tmp_path / "s.xosc").write_text(LIGHTS.replace("PHASES", phases).replace("CTL", ref))
    return import_xosc(tmp_path / "s.xosc", lenient=True)


def test_signal_controller_phases_become_a_program(tmp_path):
    """Phases red 10 s, green 5 s, yellow 2 s: the program green 5 s, yellow 2 s, red 10 s
    whose green starts at 10 s; a controller action resumes the program (W0802, with its
    line), a controller condition on a phase is `light(C) == S` of that phase's colour."""
    phases = _phase("stop", 10, "on;off;off") + _phase("go", 5, "off;off;on") + _phase("wait", 2, "off;on;off")
    got = _lights_file(tmp_path, phases)
    assert got.text is not None, [d.message for d in got.diagnostics]
    (ctl,) = got.plan.controllers
    assert (ctl.name, ctl.signals) == ("west", ["1", "2"])
    assert [e.value for e in (ctl.green_s, ctl.yellow_s, ctl.red_s, ctl.offset_s)] == [5.0, 2.0, 10.0, 10.0]
    assert "at 4 s light west state program" in got.text
    assert "when light(west) == green then behavior" in got.text
    resume = next(d for d in got.diagnostics if "resumes its program" in d.message)
    assert resume.code == "W0802" and resume.span.line == 29 and resume.label == "<TrafficSignalControllerAction>"
    assert not [d for d in got.diagnostics if d.code == "W0801"], [d.message for d in got.diagnostics]
    # The program is the file's: red until 10 s, then green for 5 s, yellow for 2 s.
    from addt_dsl.runtime.lights import Program
    program = Program(5.0, 2.0, 10.0, 10.0)
    assert [program.state(t) for t in (0.0, 9.9, 10.1, 15.5, 17.5, 27.1)] == [2.0, 2.0, 0.0, 1.0, 2.0, 0.0]


def test_signal_controller_problems_are_diagnostics(tmp_path):
    # Phases out of the language's order: one cycle of their summed times, said with the line.
    odd = _phase("go", 5, "off;off;on") + _phase("stop", 10, "on;off;off") + _phase("wait", 2, "off;on;off")
    got = _lights_file(tmp_path, odd)
    assert got.text is not None
    approx = next(d for d in got.diagnostics if "as one green, yellow, red cycle" in d.message)
    assert approx.code == "W0802" and approx.span.line == 6 and approx.label == "<TrafficSignalController>"
    # A controller action on a controller the file does not have: an error, nothing written.
    got = _lights_file(tmp_path, odd, ref="east")
    assert got.text is None
    err = next(d for d in got.diagnostics if d.is_error)
    assert "no traffic signal controller 'east'" in err.message and err.span.line == 29
    # A lamp state that shows no one colour: not translated, with its element.
    got = _lights_file(tmp_path, _phase("x", 5, "on;on;off") + _phase("go", 5, "off;off;on"))
    bad = next(d for d in got.diagnostics if "shows no one colour" in d.message)
    assert bad.code == "W0801" and bad.label == "<TrafficSignalState>"


def test_lights_come_back_from_the_xosc_alone(tmp_path):
    spec = expand(compile_file(ROOT / "tests" / "data" / "interop" / "every_light.addt").plan).specs[0]
    got = _without_sidecar(spec, tmp_path)
    ctls = {c.name: c for c in got.plan.controllers}
    assert ctls["main"].signals == ["1", "2"] and ctls["other"].signals == ["3"]
    # The program's offset is in the phases' order: the same program comes back.
    assert [e.value for e in (ctls["main"].green_s, ctls["main"].yellow_s, ctls["main"].red_s,
                              ctls["main"].offset_s)] == [60.0, 2.0, 20.0, 1.0]
    steps = [(tr.clause.name, tr.clause.settings["state"]) for tr in got.plan.light_steps]
    assert steps == [("main", "red"), ("main", "program"), ("other", "yellow"), ("other", "green")]
    assert "when light(main) == red then light other state green" in got.text
    assert "when light(main) == red then behavior cruise" in got.text
    assert all(a.ignore_lights for a in got.plan.agents)  # OpenSCENARIO's actors follow their actions


def test_environment_changes_in_events_are_environment_steps():
    # esmini's cut-in_environment.xosc: times of day at 1, 4, 7 s (2025-06-13, day 164), dense
    # fog at 10 s lifted at 13 s, several changes at 15 s and the catalog's "winter" at 17 s.
    got = import_xosc(ESMINI / "xosc" / "cut-in_environment.xosc", root=ESMINI)
    assert got.text is not None, [d.message for d in got.diagnostics if d.is_error]
    steps = [(t.at_s.value, t.clause.name, {k: v.value for k, v in t.clause.settings.items()})
             for t in got.plan.environment_steps]
    assert steps[:5] == [(1.0, "light", {"time": 0.0, "day": 164.0}), (4.0, "light", {"time": 21600.0, "day": 164.0}),
                         (7.0, "light", {"time": 43200.0, "day": 164.0}), (10.0, "fog", {"visibility": 20.0}),
                         (13.0, "fog", {"visibility": 10000.0})]
    assert sorted(s[1:] for s in steps if s[0] == 15.0) == sorted(
        [("road", {"friction": 0.9}), ("fog", {"visibility": 10000.0}), ("rain", {"rate": 0.0}),
         ("light", {"sun": 0.4})])
    assert sorted(s[1:] for s in steps if s[0] == 17.0) == sorted(  # the catalog's winter
        [("road", {"friction": 0.5}), ("fog", {"visibility": 300.0}), ("light", {"sun": 0.3})])
    said = {d.message for d in got.diagnostics if d.code == "W0802"}
    assert "precipitation snow: no model (rain, fog, light are)" in said
    assert any(m.startswith("<Wind>, fractionalCloudCover, temperature, atmosphericPressure: no model") for m in said)



@pytest.mark.parametrize("event", ["fogEventDense", "nightTimeEvent"])
def test_an_environment_step_that_runs_more_than_once_is_refused(tmp_path, event):
    """A global action's event with maximumExecutionCount > 1 ran once (its repeats dropped)."""
    shutil.copytree(ESMINI, tmp_path / "esmini")
    path = tmp_path / "esmini" / "xosc" / "cut-in_environment.xosc"
    text = path.read_text()
    old = f'<Event name="{event}" priority="overwrite" maximumExecutionCount="1">'
    assert old in text
    path.write_text(text.replace(old, old.replace('Count="1"', 'Count="2"')))
    got = import_xosc(path, root=tmp_path / "esmini")
    assert got.text is None
    assert "an environment step that runs more than once is not translated" in \
        {d.message for d in got.diagnostics if d.code == "E0803"}

SHAPED = """<?xml version="1.0"?>
<OpenSCENARIO>
  <FileHeader revMajor="1" revMinor="2" date="2024-01-01T00:00:00" description="d" author="a"/>
  <RoadNetwork><LogicFile filepath="r.xodr"/></RoadNetwork>
  <Entities>
    <ScenarioObject name="Ego"><Vehicle name="c" vehicleCategory="car"><BoundingBox><Center x="0" y="0" z="0.7"/>
      <Dimensions width="2" length="4.5" height="1.4"/></BoundingBox></Vehicle></ScenarioObject>
    <ScenarioObject name="a"><Vehicle name="c" vehicleCategory="car"><BoundingBox><Center x="0" y="0" z="0.7"/>
      <Dimensions width="2" length="4.5" height="1.4"/></BoundingBox></Vehicle></ScenarioObject>
  </Entities>
  <Storyboard>
    <Init><Actions>
      <Private entityRef="Ego"><PrivateAction><TeleportAction><Position>
        <LanePosition roadId="1" laneId="-1" s="20" offset="0"/></Position></TeleportAction></PrivateAction></Private>
      <Private entityRef="a">
        <PrivateAction><TeleportAction><Position>
          <LanePosition roadId="1" laneId="-1" s="100" offset="0"/></Position></TeleportAction></PrivateAction>
        <PrivateAction><RoutingAction><FollowTrajectoryAction>
          <Trajectory name="t" closed="false"><Shape>SHAPE</Shape></Trajectory>
          <TimeReference><Timing domainAbsoluteRelative="relative" offset="0" scale="1"/></TimeReference>
          <TrajectoryFollowingMode followingMode="position"/>
        </FollowTrajectoryAction></RoutingAction></PrivateAction>
      </Private>
    </Actions></Init>
    <StopTrigger/>
  </Storyboard>
</OpenSCENARIO>
"""
START = '<Position><LanePosition roadId="1" laneId="-1" s="100" offset="0"/></Position>'


def _shaped(tmp_path, shape):
    (tmp_path / "r.xodr").write_text((ESMINI / "xodr" / "straight_500m.xodr").read_text())
    (tmp_path / "s.xosc").write_text(SHAPED.replace("SHAPE", shape))
    got = import_xosc(tmp_path / "s.xosc")
    assert got.text is not None, [d.message for d in got.diagnostics]
    (traj,) = next(a for a in got.plan.agents if a.name == "a").behaviors
    xs, ys = ([v.value for v in traj.settings[k]] for k in ("x", "y"))
    times = [v.value for v in traj.settings.get("times", [])]
    return got, xs, ys, times


@pytest.mark.parametrize("curvature, end", [(0.0, (40.0, 0.0)), (1 / 20.0, (0.0, 40.0))])
def test_a_clothoid_is_sampled_as_a_world_polyline(curvature, end, tmp_path):
    """Straight (k = 0) and a half circle of radius 20 m (k = 1/20, length 20 pi m): the
    samples lie on the curve from the start pose, timed linearly along it."""
    length = 40.0 if curvature == 0 else 20 * np.pi
    got, xs, ys, times = _shaped(tmp_path, f'<Clothoid curvature="{curvature}" curvatureDot="0" length="{length}" '
                                           f'startTime="1" stopTime="5">{START}</Clothoid>')
    x0, y0 = xs[0], ys[0]
    assert (xs[-1] - x0, ys[-1] - y0) == pytest.approx(end, abs=1e-3)
    if curvature:  # every sample is 20 m from the circle's centre, left of the start
        assert np.allclose(np.hypot(np.array(xs) - x0, np.array(ys) - (y0 + 20.0)), 20.0, atol=1e-3)
    assert times[0] == 1.0 and times[-1] == pytest.approx(5.0) and np.all(np.diff(times) > 0)
    warn = next(d for d in got.diagnostics if d.label == "<Clothoid>")
    assert warn.code == "W0802" and "sampled as a polyline" in warn.message and warn.span.line == 19


def test_a_nurbs_is_sampled_with_its_basis(tmp_path):
    """A clamped quadratic NURBS of three control points with unit weights passes through
    its end points and, half way, through P0/4 + P1/2 + P2/4; times by the same basis."""
    cps = "".join(f'<ControlPoint time="{t}" weight="1"><Position><LanePosition roadId="1" laneId="-1" s="{s}" '
                  f'offset="{o}"/></Position></ControlPoint>' for t, s, o in ((0, 100, 0), (2, 120, 3), (6, 140, 0)))
    knots = "".join(f'<Knot value="{k}"/>' for k in (0, 0, 0, 1, 1, 1))
    got, xs, ys, times = _shaped(tmp_path, f'<Nurbs order="3">{cps}{knots}</Nurbs>')
    y0 = ys[0]
    assert xs[0] == pytest.approx(100.0) and xs[-1] == pytest.approx(140.0, abs=1e-6)
    mid = len(xs) // 2
    assert (xs[mid], ys[mid] - y0) == pytest.approx((120.0, 1.5))
    assert (times[0], times[mid], times[-1]) == pytest.approx((0.0, 2.5, 6.0), abs=1e-6)
    bad = SHAPED.replace("SHAPE", f'<Nurbs order="3">{cps}<Knot value="0"/></Nurbs>')
    (tmp_path / "s.xosc").write_text(bad)
    err = next(d for d in import_xosc(tmp_path / "s.xosc").diagnostics if d.is_error)
    assert "needs 6 non-decreasing knots" in err.message and err.label == "<Nurbs>"


def test_route_catalogs_and_route_positions(tmp_path):
    """esmini's ltap-od places both cars with RoutePositions on routes of a route catalog
    and assigns those routes: each actor drives its route from where pathS puts it."""
    got = import_xosc(ESMINI / "xosc" / "ltap-od.xosc", root=ESMINI)
    assert got.text is not None
    actors = {a.name: a for a in got.plan.actors()}
    params = {p.name: p.default for p in got.plan.params}
    # HostStraightRoute: road 0 lane 1 (driven against s) from s = 63 m, pathS 0: `at 63 m`,
    # the first road's station (on a route too; it was written as 30.66 m, the distance from
    # the route's entry end, which placed the ego 32 m from where esmini has it).
    assert actors["ego"].route == ["0", "9", "2"] and actors["ego"].lane.value == 1.0
    assert eval_param_expr(actors["ego"].s, params) == pytest.approx(63.0)
    # TargetLeftTurnRoute: road 2 lane -1 from s = 100 m, pathS = NPCStartPointS (150 m).
    assert actors["NPC"].route == ["2", "15", "1"] and eval_param_expr(actors["NPC"].s, params) == 250.0
    assert not any("Route" in d.message or "first road" in d.message for d in got.diagnostics), \
        [d.message for d in got.diagnostics]


ROUTED = SHAPED.replace("straight_500m", "x").replace(
    '<LanePosition roadId="1" laneId="-1" s="20" offset="0"/>',
    '<RoutePosition><RouteRef><Route name="r" closed="false">'
    '<Waypoint routeStrategy="shortest"><Position><LanePosition roadId="0" laneId="1" s="63" offset="0"/></Position>'
    '</Waypoint><Waypoint routeStrategy="shortest"><Position><LanePosition roadId="2" laneId="1" s="5" offset="0"/>'
    '</Position></Waypoint></Route></RouteRef>'
    '<InRoutePosition><FromLaneCoordinates pathS="10" laneId="LANE"/></InRoutePosition></RoutePosition>')


@pytest.mark.parametrize("lane", ["1", "5"])
def test_an_inline_route_position(lane, tmp_path):
    (tmp_path / "r.xodr").write_text((ESMINI / "xodr" / "fabriksgatan.xodr").read_text())
    text = ROUTED.replace("LANE", lane)
    text = text.replace('<LanePosition roadId="1" laneId="-1" s="100" offset="0"/>',
                        '<LanePosition roadId="2" laneId="-1" s="100" offset="0"/>')
    text = re.sub(r"<PrivateAction><RoutingAction><FollowTrajectoryAction>.*?</PrivateAction>", "", text, flags=re.S)
    (tmp_path / "s.xosc").write_text(text)
    got = import_xosc(tmp_path / "s.xosc", lenient=True)
    assert got.text is not None, [d.message for d in got.diagnostics]
    ego = got.plan.ego
    if lane == "1":  # 10 m along the route from s = 63 m of road 0, which lane 1 drives against s
        assert ego.route == ["0", "9", "2"]
        assert eval_param_expr(ego.s, {}) == pytest.approx(53.0)  # `at` is road 0's station
        placed = next(d for d in got.diagnostics if "nothing assigns" in d.message)
        assert placed.code == "W0802" and placed.label == "<Route>"
    else:
        miss = next(d for d in got.diagnostics if "leads along the route to lane 5" in d.message)
        assert miss.code == "W0801" and miss.label == "<RoutePosition>" and miss.span.line == 14


def test_a_controller_name_the_language_cannot_spell_is_renamed_everywhere(tmp_path):
    phases = _phase("stop", 10, "on;off;off") + _phase("go", 5, "off;off;on") + _phase("wait", 2, "off;on;off")
    (tmp_path / "m.xodr").write_text((ESMINI / "xodr" / "fabriksgatan_traffic_lights.xodr").read_text())
    text = LIGHTS.replace("PHASES", phases).replace('"west"', '"west light"').replace("CTL", "west light")
    (tmp_path / "s.xosc").write_text(text)
    got = import_xosc(tmp_path / "s.xosc")
    assert got.text is not None, [d.message for d in got.diagnostics]
    (ctl,) = got.plan.controllers
    assert "light(" + ctl.name + ") == green" in got.text and f"light {ctl.name} state program" in got.text


@pytest.mark.parametrize("green, yellow, red, offset", [(5, 2, 10, 0), (5, 2, 10, 3), (5, 2, 10, 6),
                                                        (5, 2, 10, 16.5), (4, 0, 6, 9), (0, 3, 7, 2), (20, 3, 20, 41)])
def test_a_programs_phases_carry_its_offset(green, yellow, red, offset, tmp_path):
    """Export writes a program as phases from time 0 (an offset rotates and splits them);
    the import reads the same program back from the .xosc alone."""
    from addt_dsl.runtime.lights import Program

    source = f"""scenario p {{
  duration 5 s
  road r {{
    line length 300 m
    lanes right 1
  }}
  lights {{
    signal s1 road r at 100 m
    controller c signals [s1] green {green} s yellow {yellow} s red {red} s offset {offset} s
  }}
  ego car on r lane -1 at 10 m speed 5 m/s
}}
"""
    spec = expand(compile_source(source, "p.addt").plan).specs[0]
    got = _without_sidecar(spec, tmp_path)
    (ctl,) = got.plan.controllers
    back = Program(*(e.value for e in (ctl.green_s, ctl.yellow_s, ctl.red_s, ctl.offset_s)))
    times = np.arange(0.0, 120.0, 0.25) + 0.01
    assert np.array_equal(back.state(times), Program(green, yellow, red, offset).state(times))
    assert not any(d.code == "W0802" and "cycle" in d.message for d in got.diagnostics)


def _json_leaves(node, path=()):
    """Paths to every value of a JSON tree (containers included)."""
    yield path
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _json_leaves(v, (*path, k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _json_leaves(v, (*path, i))


@pytest.fixture(scope="module")
def exported_with_side_file(tmp_path_factory):
    spec = expand(compile_file(ROOT / "tests" / "data" / "interop" / "every_action.addt").plan).specs[0]
    done = export_run(spec, tmp_path_factory.mktemp("export"))
    return done.xosc_path, done.sidecar_path, json.loads(done.sidecar_path.read_text())


SIDE_VALUES = st.one_of(st.none(), st.booleans(), st.integers(-2**70, 2**70), st.floats(allow_nan=True),
                        st.text(max_size=8), st.just([]), st.just({}), st.just([[[[[]]]]]), st.just({"kind": "num"}),
                        st.just({"keyword": "stack", "name": "nope", "settings": {}}))


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_any_value_anywhere_in_a_side_file_is_imported_or_a_diagnostic(exported_with_side_file, data):
    """Fuzz: one value of an exported side file replaced by a hostile one (any JSON type,
    huge or non-finite numbers, containers of the wrong shape): the import gives a scenario
    that compiles or diagnostics, never an exception."""
    xosc, side, original = exported_with_side_file
    paths = sorted((p for p in _json_leaves(original) if p), key=repr)
    path = data.draw(st.sampled_from(paths))
    value = data.draw(SIDE_VALUES)
    doc = json.loads(json.dumps(original))
    node = doc
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    side.write_text(json.dumps(doc))
    try:
        got = import_xosc(xosc)
    finally:
        side.write_text(json.dumps(original))
    assert got.text is not None or any(d.is_error for d in got.diagnostics)
    assert "E0900" not in {d.code for d in got.diagnostics}


WRONG_SHAPES = [  # found by the fuzz test above; each raised from the import (TypeError, KeyError, ...)
    ("every_action", ("description",), None), ("every_action", ("description",), []),
    ("every_action", ("seed",), None), ("every_action", ("run_seed",), []),
    ("every_action", ("actors", "ego", "route"), True), ("every_action", ("actors", "ego", "yaw"), "x"),
    ("every_action", ("actors", "ego", "wheelbase_m"), None),
    ("every_action", ("actors", "ego", "stack", "keyword"), "x"),
    ("every_light", ("lights", "steps", "light_main_red", "name"), "x"),
    ("every_light", ("lights", "steps", "light_main_red", "settings"), {}),
    ("every_behavior", ("conditions", "addt_condition_1", "formula", "left", "args"), []),
]


@pytest.mark.parametrize(("example", "path", "value"), WRONG_SHAPES)
def test_a_side_file_value_of_the_wrong_shape_is_a_diagnostic(example, path, value, tmp_path):
    spec = expand(compile_file(ROOT / "tests" / "data" / "interop" / f"{example}.addt").plan).specs[0]
    done = export_run(spec, tmp_path)
    doc = json.loads(done.sidecar_path.read_text())
    node = doc
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    done.sidecar_path.write_text(json.dumps(doc))
    got = import_xosc(done.xosc_path)
    assert got.text is None
    assert any(d.code == "E0802" for d in got.diagnostics), got.diagnostics


def test_direction_reverse_survives_export_and_import_without_the_side_file(tmp_path):
    from addt_dsl.interop.xosc_export import export_run
    from addt_dsl.sweep import expand
    source = """scenario wrong_way {
  duration 4 s
  road r {
    line length 300 m
    lanes left 1 right 1 width 3.5 m
  }
  ego car on r lane -1 at 10 m speed 0 m/s
  agent over car on r lane 1 at 100 m speed 10 m/s direction reverse
  agent oncoming car on r lane 1 at 200 m speed 10 m/s
}
"""
    done = export_run(expand(compile_source(source).plan).specs[0], tmp_path)
    xml = done.xosc_path.read_text()
    assert 'h="3.14159' in xml  # an Orientation against the lane, relative to it
    done.sidecar_path.unlink()
    back = import_xosc(done.xosc_path)
    assert back.plan is not None, [str(d) for d in back.diagnostics]
    flags = {a.name: a.reverse for a in back.plan.agents}
    assert flags == {"over": True, "oncoming": False}


def test_edges_and_delays_survive_export_and_import_without_the_side_file(tmp_path):
    from addt_dsl.interop.xosc_export import export_run
    from addt_dsl.sweep import expand
    source = """scenario edges {
  duration 6 s
  road r {
    line length 800 m
    lanes right 2 width 3.5 m
  }
  ego car on r lane -2 at 10 m speed 0 m/s
  agent a car on r lane -1 at 100 m speed 10 m/s {
    when rising speed(a) > 5 m/s then behavior brake decel 1 m/s^2
    when falling speed(a) > 9.5 m/s delayed 1 s then behavior cruise speed 20 m/s
  }
  end when rising speed(a) < 1 m/s delayed 1 s
}
"""
    done = export_run(expand(compile_source(source).plan).specs[0], tmp_path)
    xml = done.xosc_path.read_text()
    assert 'delay="1.0" conditionEdge="falling"' in xml and 'conditionEdge="rising"' in xml
    done.sidecar_path.unlink()
    back = import_xosc(done.xosc_path)
    assert back.plan is not None, [str(d) for d in back.diagnostics]
    # (the brake comes back as a change to 0 m/s at its rate: `cruise`)
    steps = sorted((t.clause.settings["speed"].value, t.edge, t.delay_s.value if t.delay_s else None)
                   for t in back.plan.agents[0].triggers)
    assert steps == [(0.0, "rising", None), (20.0, "falling", 1.0)]
    end = back.plan.end  # the storyboard's stop trigger, beside the duration's group
    assert (end.edge, end.delay_s.value, back.plan.duration_s) == ("rising", 1.0, 6.0)


def test_a_lane_offset_is_along_the_roads_t_in_openscenario_and_to_the_drivers_left_here(tmp_path):
    # OpenSCENARIO's LanePosition offset is along the road's t; the language's `offset` is to
    # the driver's left, the other way on a lane driven against s (esmini's walkers were 1 m
    # off, CARLA's CyclistCrossing hero 1 m from its WorldPosition).
    from addt_dsl.interop.xosc_export import export_run
    from addt_dsl.sweep import expand
    source = """scenario offsets {
  duration 2 s
  road r {
    line length 300 m
    lanes left 1 right 1 width 3.5 m
  }
  ego car on r lane -1 at 10 m speed 0 m/s offset 0.25 m
  agent oncoming car on r lane 1 at 200 m speed 10 m/s offset 0.5 m
}
"""
    done = export_run(expand(compile_source(source).plan).specs[0], tmp_path)
    xml = done.xosc_path.read_text()
    assert 'offset="0.25"' in xml and 'offset="-0.5"' in xml
    done.sidecar_path.unlink()
    back = import_xosc(done.xosc_path)
    assert back.plan is not None, [str(d) for d in back.diagnostics]
    assert back.plan.agents[0].offset.value == pytest.approx(0.5)
    assert back.plan.ego.offset.value == pytest.approx(0.25)


def test_a_follow_speed_profile_imports_with_its_dynamic_constraints(tmp_path):
    """followingMode follow is `mode follow` with the DynamicConstraints (speed-profile.xosc's
    Car1, the ego); in position mode a slope beyond them is met as given, with a W0802."""
    got = import_xosc(ESMINI / "xosc" / "speed-profile.xosc", root=ESMINI, ego="scripted")
    assert got.text is not None, [d.message for d in got.diagnostics]
    profiles = {a.name: next(t.clause for t in a.triggers) for a in got.plan.actors()}
    follow = profiles["ego"].settings
    assert follow["mode"] == "follow"
    assert {k: follow[k].value for k in ("accel", "decel", "accel_rate", "decel_rate", "max_speed")} == {
        "accel": 5.0, "decel": 10.0, "accel_rate": 4.0, "decel_rate": 3.0, "max_speed": 50.0}
    assert "mode" not in profiles["Car2"].settings and "accel" not in profiles["Car2"].settings
    assert not [d for d in got.diagnostics if d.label == "<SpeedProfileAction>"]
    # Car2 (position mode) 0 -> 10 m/s in 1 s: 10 m/s^2 beyond maxAcceleration 5.
    text = (ESMINI / "xosc" / "speed-profile.xosc").read_text()
    head, tail = text.split('followingMode="position"')
    steep = head + 'followingMode="position"' + tail.replace('time="4.0" speed="10.0"', 'time="1.0" speed="10.0"', 1)
    (tmp_path / "xosc").mkdir()
    shutil.copytree(ESMINI / "xodr", tmp_path / "xodr")
    shutil.copytree(ESMINI / "xosc" / "Catalogs", tmp_path / "xosc" / "Catalogs")
    (tmp_path / "xosc" / "s.xosc").write_text(steep)
    got = import_xosc(tmp_path / "xosc" / "s.xosc", root=tmp_path, ego="scripted")
    warns = [d for d in got.diagnostics if d.label == "<SpeedProfileAction>"]
    assert [d.code for d in warns] == ["W0802"] and "beyond the DynamicConstraints" in warns[0].message


def test_time_to_collision_in_entity_coordinates_is_the_gap_along_the_heading():
    """pedestrian.xosc: TimeToCollisionCondition freespace, coordinateSystem entity,
    longitudinal: the boxes' gap along the ego's heading (`lon_gap`), its box 1.4 m and the
    walker's 0.06 m ahead of their reference points (the actors' centres); was the gap
    along the road, on different roads the Euclidean one, which braked 0.2 s late."""
    got = import_xosc(ESMINI / "xosc" / "pedestrian.xosc", root=ESMINI, ego="scripted")
    assert got.text is not None, [d.message for d in got.diagnostics]
    assert "lon_gap(ego, pedestrian_adult) - 1.34 m < 1.2 s * (speed(ego) - speed(pedestrian_adult))" in got.text
    said = [d.message for d in got.diagnostics if d.code == "W0802"]
    assert any(m.startswith("time to collision in entity coordinates") for m in said)


def test_lane_change_xosc_translates_every_construct_strictly():
    """esmini's lane_change.xosc imports without --lenient: the ego's LaneOffsetAction (8 m,
    sinusoidal, 3.5 m/s^2) in lane 1 is 8 m toward +t (esmini: the value times the sign of
    the lane id); the truck in lane 1 drives against s, so a lane to its left (+1) is lane
    -1, not 2; its ParameterCondition reads the parameter an event's ParameterSetAction sets
    (a scenario variable); the OffroadCondition held 2.5 s is `road_edge(ego) < 0 m for
    2.5 s`; the stop trigger waits on that event's end; both actors stop at the road's end."""
    got = import_xosc(ESMINI / "xosc" / "lane_change.xosc", root=ESMINI, ego="scripted")
    assert got.text is not None, [d.message for d in got.diagnostics if d.is_error]
    for line in ("behavior lane_offset to 8 m max_lat_accel 3.5 m/s^2 shape sinusoidal",
                 "EgoGoOnRoadEvent: when road_edge(ego) < 0 m for 2.5 s then behavior lane_change to 1 duration 3 s",
                 "when rising var(DummyParameter) > 10 then behavior lane_change to -1 duration 2 s shape sinusoidal",
                 "DummyParameter = 2", "at 3 s set DummyParameter 11",
                 "end when rising ended(ego.EgoGoOnRoadEvent) delayed 3 s"):
        assert line in got.text, line
    assert got.text.count("at_road_end stop") == 2
    warned = [d.message for d in got.diagnostics if d.code == "W0802"]
    assert any("off the road for 2.5 s" in m for m in warned), warned


def test_an_offroad_duration_beside_another_condition_is_refused(tmp_path):
    shutil.copytree(ESMINI, tmp_path / "esmini")
    path = tmp_path / "esmini" / "xosc" / "lane_change.xosc"
    text = path.read_text()
    cond = text[text.index('<Condition name="EgoGoOnRoadCondition"'):]
    cond = cond[:cond.index("</Condition>") + len("</Condition>")]
    path.write_text(text.replace(cond, cond + cond.replace("EgoGoOnRoadCondition", "Second"), 1))
    got = import_xosc(path, root=tmp_path / "esmini", ego="scripted")
    assert got.text is None
    assert any(d.code == "E0803" and "off-road duration" in d.message for d in got.diagnostics)


def test_a_lane_offset_comes_back_from_the_xosc_alone(tmp_path):
    """`lane_offset` exports as a LaneOffsetAction (esmini's sign: a right lane's offset to
    the left of +s is a negative value) and imports back to the same behaviour."""
    source = """scenario offsets {
  duration 5 s
  road r {
    line length 300 m
    lanes right 2
  }
  ego car on r lane -2 at 10 m speed 10 m/s {
    stack bev cruise_speed 10 m/s
  }
  agent drifter car on r lane -1 at 20 m speed 10 m/s {
    at 1 s behavior lane_offset to 1.2 m max_lat_accel 1.5 m/s^2 shape sinusoidal
  }
}
"""
    spec = expand(compile_source(source, "offsets.addt").plan).specs[0]
    done = export_run(spec, tmp_path, "scenario")
    target = ET.parse(done.xosc_path).getroot().find(".//LaneOffsetAction/LaneOffsetTarget/AbsoluteTargetLaneOffset")
    assert float(target.get("value")) == -1.2
    got = _without_sidecar(spec, tmp_path / "again")
    (step,) = next(a for a in got.plan.agents if a.name == "drifter").triggers
    assert step.clause.name == "lane_offset" and step.clause.settings["shape"] == "sinusoidal"
    assert (step.clause.settings["to"].value, step.clause.settings["max_lat_accel"].value) == (1.2, 1.5)


def test_a_relative_orientation_on_a_lane_position_is_the_bodys_yaw():
    # alks_cut-out's Box: <LanePosition ...><Orientation type="relative" h="0.1"/>: esmini
    # stands it at 0.1 rad to its lane (its trajectory's heading 0.10000 at t = 0); it stood
    # along the lane.
    got = import_xosc(ROOT / "tests" / "data" / "esmini" / "xosc" / "alks_cut-out.xosc",
                      root=ROOT / "tests" / "data" / "esmini")
    box = next(a for a in got.plan.agents if a.name == "Box")
    assert box.yaw is not None and box.yaw.value == 0.1
    assert "yaw 0.1 rad" in got.text


def test_a_pitch_or_roll_is_said_not_modelled():
    # bicycle_fall_over's trajectory rolls the cyclist over (r = 1.5 rad): the twin keeps
    # bodies level, so the import says so (W0802) rather than dropping it.
    got = import_xosc(ROOT / "tests" / "data" / "esmini" / "xosc" / "bicycle_fall_over.xosc",
                      root=ROOT / "tests" / "data" / "esmini", ego="scripted")
    rolls = [d for d in got.diagnostics if d.code == "W0802" and "roll 1.5 rad" in d.message]
    assert len(rolls) == 3 and "not modelled" in rolls[0].message
    # A zero pitch and roll (pedestrian's Orientation p="0" r="0") is no warning.
    quiet = import_xosc(ROOT / "tests" / "data" / "esmini" / "xosc" / "pedestrian.xosc",
                        root=ROOT / "tests" / "data" / "esmini", ego="scripted")
    assert not [d for d in quiet.diagnostics if "pitch" in d.message or "roll" in d.message]
    # pedestrian_collision lays its walker down (a teleport in place, roll 1.57 rad) and back up.
    down = import_xosc(ROOT / "tests" / "data" / "esmini" / "xosc" / "pedestrian_collision.xosc",
                       root=ROOT / "tests" / "data" / "esmini", ego="scripted")
    assert [d.message.split(":")[0] for d in down.diagnostics if "roll" in d.message] == \
        ["roll 1.57 rad of pedestrian_adult", "roll -1.57 rad of pedestrian_adult"]


def test_a_teleport_that_turns_the_actor_says_it_does_not(tmp_path):
    # lane_change_simple's teleport back to s = 10 m, given a heading (0.5 rad to its lane):
    # the language's `teleport` moves and does not turn, so the import says so (W0802); the
    # same teleport facing its lane (h = 0) is said nothing.
    text = (ESMINI / "xosc" / "lane_change_simple.xosc").read_text()
    lane = '<LanePosition roadId="0" laneId="-1" offset="0" s="10"/>'
    assert lane in text
    shutil.copytree(ESMINI, tmp_path / "esmini")
    path = tmp_path / "esmini" / "xosc" / "turned.xosc"
    said = {}
    for h in ("0.5", "0"):
        path.write_text(text.replace(lane, lane[:-2] + f'><Orientation type="relative" h="{h}"/></LanePosition>'))
        got = import_xosc(path, root=tmp_path / "esmini", lenient=True, ego="scripted")
        said[h] = [d.message for d in got.diagnostics if "heading after the teleport" in d.message]
    assert len(said["0.5"]) == 2 and "does not turn" in said["0.5"][0] and said["0"] == []


def test_a_heading_on_an_entity_moving_from_the_start_is_said_to_give_way_to_its_path(tmp_path):
    # cut-in_simple's OverTaker starts at speed facing its lane (absolute h = 0 on a road
    # along +x): nothing said. Turned 0.2 rad, it is placed with that yaw, but an agent
    # moving from the start follows its path from t = 0: W0802 says so.
    text = (ESMINI / "xosc" / "cut-in_simple.xosc").read_text()
    orient = '<Orientation type="absolute" h="0"'
    shutil.copytree(ESMINI, tmp_path / "esmini")
    path = tmp_path / "esmini" / "xosc" / "turned.xosc"
    for h, said in (("0", 0), ("0.2", 1)):
        path.write_text(text.replace(orient, orient.replace('h="0"', f'h="{h}"')))
        got = import_xosc(path, root=tmp_path / "esmini")
        notes = [d.message for d in got.diagnostics if "moves from the start" in d.message]
        assert len(notes) == said, notes
        assert ("yaw 0.2 rad" in got.text) == bool(said)
