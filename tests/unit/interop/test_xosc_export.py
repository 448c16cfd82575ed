"""`addtc export`: every example's run as OpenSCENARIO 1.2 + OpenDRIVE that the ASAM
checkers accept without errors; what OpenSCENARIO cannot hold is listed and carried."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from defusedxml import ElementTree as DET

from addt_dsl.cli import main
from addt_dsl.compiler import compile_file, compile_source
from addt_dsl.interop.openscenario.sidefile import SIDE_FILE_KEYS, SIDECAR_FORMAT
from addt_dsl.interop.openscenario.importer import import_xosc
from addt_dsl.interop.xosc_export import export_run
from addt_dsl.road import parse_xodr
from addt_dsl.road.roadspec import build_network
from addt_dsl.sweep import expand
from tests.conftest import EXAMPLES, ROOT, needs_torch
from tests.unit.interop.asam_qc import check, problems


def done_ids(done, plan) -> dict[str, str]:
    """Plan road name -> OpenDRIVE road id in the export (inline roads: 1, 2, ...)."""
    return {r.name: str(i) for i, r in enumerate(plan.roads, start=1)}

SCENARIOS = sorted(EXAMPLES.glob("*.addt")) + [ROOT / "tests" / "data" / "interop" / f"{n}.addt"
                                               for n in ("every_behavior", "every_action", "every_light",
                                                         "every_road_end")] + [
    ROOT / "tests" / "unit" / "compiler" / "cases" / "scripted_ego_ok.addt"]


@pytest.mark.parametrize("path", SCENARIOS, ids=[p.stem for p in SCENARIOS])
def test_export_passes_the_asam_checkers(path, tmp_path):
    if needs_torch(path):
        pytest.importorskip("torch")
    plan = compile_file(path).plan
    spec = expand(plan).specs[0]
    done = export_run(spec, tmp_path, path.stem)
    assert problems(done.xosc_path, "qc_openscenario") == []
    inline = [r for r in plan.roads if r.source == "inline"]
    if inline:  # generated as OpenDRIVE 1.8, so the checker's version-gated checks run
        assert problems(done.xodr_path, "qc_opendrive") == []  # (an imported map is copied as it is)
        ran = [c for c, status, _ in check(done.xodr_path, "qc_opendrive") if status == "COMPLETED"]
        assert len(ran) >= 20, ran
    # The generated road is the road the twin built: lane centres agree to rounding.
    built = build_network(inline)
    exported = parse_xodr(done.xodr_path.read_text(), done.xodr_path.name)
    for road in inline:
        a, b = built[road.name].road(road.name), exported.road(done_ids(done, plan)[road.name])
        for lane in (i for i in a.lane_ids(0.0) if i != 0):
            for s in np.linspace(0.0, a.length - 1e-6, 50):
                assert np.allclose(a.lane_center(lane, s), b.lane_center(lane, s), atol=1e-9, rtol=0)
    root = DET.parse(done.xosc_path).getroot()
    header = root.find("FileHeader")
    assert (header.get("revMajor"), header.get("revMinor")) == ("1", "2")
    assert {o.get("name") for o in root.iterfind("Entities/ScenarioObject")} == {a.name for a in plan.actors()}
    side = json.loads(done.sidecar_path.read_text())
    assert side["format"] == SIDECAR_FORMAT and side["run_seed"] == spec.seed
    assert sorted(side) == sorted(SIDE_FILE_KEYS)  # the keys the import checks, one definition
    # Nothing OpenSCENARIO cannot say is dropped: each fault and oracle is listed and carried.
    assert len(side["faults"]) == len(spec.faults) and len(side["oracles"]) == len(plan.oracles)
    listed = "\n".join(done.carried)
    for f in spec.faults:
        assert f"fault {f.kind} {f.target}" in listed
    for o in plan.oracles:
        assert f"oracle {o.name}" in listed
    if plan.ego.stack is not None:
        assert f"stack {plan.ego.stack.name}" in listed


def test_positions_speeds_and_the_brake_trigger(tmp_path):
    spec = expand(compile_file(EXAMPLES / "lead_brake.addt").plan).specs[0]
    done = export_run(spec, tmp_path)
    root = DET.parse(done.xosc_path).getroot()
    lead = root.find("Storyboard/Init/Actions/Private[@entityRef='lead']")
    pos = lead.find(".//LanePosition")
    assert (pos.get("roadId"), pos.get("laneId"), float(pos.get("s"))) == ("1", "-1", 10.0 + spec.params["start_gap"])
    assert float(lead.find(".//AbsoluteTargetSpeed").get("value")) == spec.params["lead_speed"]
    brake = root.find(".//Event[@name='lead_brake']")
    travelled = float(brake.find(".//TraveledDistanceCondition").get("value"))
    assert travelled == spec.params["brake_at"] - (10.0 + spec.params["start_gap"])
    dyn = brake.find(".//SpeedActionDynamics")
    assert (dyn.get("dynamicsShape"), float(dyn.get("value"))) == ("linear", spec.params["decel"])
    stop = root.find("Storyboard/StopTrigger//SimulationTimeCondition")
    assert float(stop.get("value")) == spec.plan.duration_s


def test_a_scripted_ego_exports_its_script_as_an_agent_does(tmp_path):
    """The ego's behaviours and steps are events of its maneuver, its speed an Init action;
    without a stack nothing says it has one."""
    spec = expand(compile_file(ROOT / "tests" / "unit" / "compiler" / "cases" / "scripted_ego_ok.addt").plan).specs[0]
    done = export_run(spec, tmp_path)
    root = DET.parse(done.xosc_path).getroot()
    ego = root.find("Storyboard/Init/Actions/Private[@entityRef='ego']")
    assert float(ego.find(".//AbsoluteTargetSpeed").get("value")) == 15.0
    group = root.find(".//ManeuverGroup[@name='ego_maneuver_group']")
    assert group.find("Actors/EntityRef").get("entityRef") == "ego"
    names = [e.get("name") for e in group.iterfind(".//Event")]
    assert names[:2] == ["ego_cruise", "slow"] and len(names) == 10, names  # a named step's event: its name
    cruise = group.find(".//Event[@name='ego_cruise']")
    assert float(cruise.find(".//AbsoluteTargetSpeed").get("value")) == 12.0
    brake = group.find(".//Event[@name='slow']")
    gap = brake.find(".//RelativeDistanceCondition")
    assert (gap.get("entityRef"), float(gap.get("value")), gap.get("rule")) == ("lead", 20.0, "lessThan")
    assert float(brake.find("StartTrigger/ConditionGroup/Condition").get("delay")) == pytest.approx(0.2)
    assert "stack" not in "\n".join(done.carried)
    assert json.loads(done.sidecar_path.read_text())["actors"]["ego"]["stack"] is None


def test_imported_map_is_copied_with_its_road_ids(tmp_path):
    src = tmp_path / "src"
    src.mkdir()
    shutil.copy(EXAMPLES / "maps" / "straight_500m.xodr", src / "town.xodr")
    text = """scenario town {
  duration 5 s
  road main import "town.xodr" road 1
  ego car on main lane -1 at 20 m speed 10 m/s
  agent lead car on main lane -1 at 50 m speed 8 m/s { behavior cruise speed 8 m/s }
}
"""
    plan = compile_source(text, "town.addt", base_dir=src).plan
    done = export_run(expand(plan).specs[0], tmp_path / "out")
    assert done.xodr_path.name == "town.xodr"
    assert done.xodr_path.read_text() == (src / "town.xodr").read_text()
    assert DET.parse(done.xosc_path).getroot().find(".//LogicFile").get("filepath") == "town.xodr"
    assert problems(done.xosc_path, "qc_openscenario") == []


def test_cli_export_by_params_and_run(tmp_path, capsys):
    example = str(EXAMPLES / "lead_brake.addt")
    assert main(["export", example, "--params", "decel=6m/s^2", "brake_at=150", "--to", str(tmp_path / "a")]) == 0
    out = capsys.readouterr().out
    assert "carried in lead_brake.addt.json" in out and "fault drop lidar" in out
    root = DET.parse(tmp_path / "a" / "lead_brake.xosc").getroot()
    assert float(root.find(".//Event[@name='lead_brake']//SpeedActionDynamics").get("value")) == 6.0
    assert main(["export", str(EXAMPLES / "following.addt"), "--run", "c001-r000", "--to", str(tmp_path / "b")]) == 0
    spec = next(s for s in expand(compile_file(EXAMPLES / "following.addt").plan).specs if s.run_id == "c001-r000")
    side = json.loads((tmp_path / "b" / "following.addt.json").read_text())
    assert side["params"] == {k: v for k, v in spec.params.items() if k in side["params"]}
    capsys.readouterr()
    for bad in (["--run", "c999-r000"], ["--params", "nope=1"], ["--params", "decel=3 m"], ["--params", "decel=x"]):
        assert main(["export", example, *bad, "--to", str(tmp_path / "c")]) == 2
        err = capsys.readouterr().err
        assert err.startswith("error:") and "Traceback" not in err


def test_roads_from_two_sources_are_refused(tmp_path, capsys):
    shutil.copy(EXAMPLES / "maps" / "straight_500m.xodr", tmp_path / "town.xodr")
    (tmp_path / "mixed.addt").write_text("""scenario mixed {
  duration 5 s
  road main import "town.xodr" road 1
  road side { line length 100 m }
  ego car on main lane -1 at 20 m speed 10 m/s
  agent a car on side lane -1 at 20 m speed 5 m/s
}
""")
    assert main(["export", str(tmp_path / "mixed.addt"), "--to", str(tmp_path / "out")]) == 2
    assert "OpenSCENARIO references one OpenDRIVE file" in capsys.readouterr().err


def test_an_oncoming_actor_keeps_its_lane_direction(tmp_path):
    text = """scenario pos {
  duration 5 s
  road r {
    line length 300 m
    lanes right 1 left 1 width 3.5 m
  }
  ego car on r lane -1 at 20 m speed 10 m/s
  agent a car on r lane 1 at 50 m speed 8 m/s { behavior cruise speed 8 m/s }
}
"""
    done = export_run(expand(compile_source(text, "pos.addt").plan).specs[0], tmp_path)
    root = DET.parse(done.xosc_path).getroot()
    # Both languages drive an actor in its lane's OpenDRIVE direction: no orientation needed.
    assert root.find("Storyboard/Init/Actions/Private[@entityRef='ego']//Orientation") is None
    assert root.find("Storyboard/Init/Actions/Private[@entityRef='a']//Orientation") is None
    assert problems(done.xosc_path, "qc_openscenario") == []


def test_actions_are_real_openscenario(tmp_path):
    """Speed profiles, shaped and relative speed changes, lane changes to another actor's
    lane, keep_gap, synchronize, trajectories, held conditions and the environment are
    OpenSCENARIO actions in the .xosc itself, not only in the side file."""
    spec = expand(compile_file(ROOT / "tests" / "data" / "interop" / "every_action.addt").plan).specs[0]
    done = export_run(spec, tmp_path)
    root = DET.parse(done.xosc_path).getroot()

    def event(name):
        found = root.find(f".//Event[@name='{name}']")
        assert found is not None, name
        return found

    # Entry times are durations from the previous entry: points at 0, 4 and 8 s.
    entries = event("profiler_speed_profile").findall(
        ".//SpeedProfileAction[@followingMode='position']/SpeedProfileEntry")
    assert [(float(e.get("time")), float(e.get("speed"))) for e in entries] == [(0.0, 10.0), (4.0, 14.0), (4.0, 8.0)]
    dyn = event("shaper_cruise").find(".//SpeedActionDynamics")
    assert (dyn.get("dynamicsShape"), dyn.get("dynamicsDimension"), float(dyn.get("value"))) == \
        ("sinusoidal", "time", 3.0)
    lane = event("shaper_lane_change").find(".//LaneChangeAction")
    assert lane.find("LaneChangeTarget/RelativeTargetLane").attrib == {"entityRef": "profiler", "value": "0"}
    assert lane.find("LaneChangeActionDynamics").get("dynamicsShape") == "linear"
    rel = event("faster_cruise").find(".//RelativeTargetSpeed")
    assert rel.attrib == {"entityRef": "ego", "value": "1.2", "speedTargetValueType": "factor", "continuous": "true"}
    gap = event("keeper_keep_gap").find(".//LongitudinalDistanceAction")
    assert (gap.get("entityRef"), float(gap.get("distance")), gap.get("continuous")) == ("ego", 15.0, "true")
    sync = event("walker_synchronize")
    action = sync.find(".//SynchronizeAction")
    assert action.get("masterEntityRef") == "ego"
    assert float(action.find("TargetPositionMaster/LanePosition").get("s")) == 150.0
    assert float(action.find("TargetPosition/RoadPosition").get("t")) == -5.25
    # `when C for 0.5 s`: the condition's delay.
    held = sync.findall("StartTrigger/ConditionGroup/Condition")
    assert [float(c.get("delay")) for c in held] == [0.5] and held[0].find(".//RelativeDistanceCondition") is not None
    traj = event("drifter_trajectory").find(".//FollowTrajectoryAction")
    vertices = traj.findall(".//Polyline/Vertex")
    assert [float(v.get("time")) for v in vertices] == [2.0, 5.0, 8.0]
    assert [float(v.find("Position/RoadPosition").get("s")) for v in vertices] == [280.0, 250.0, 220.0]
    assert traj.find("TimeReference/Timing").get("domainAbsoluteRelative") == "relative"
    weather = root.find("Storyboard/Init/Actions/GlobalAction/EnvironmentAction/Environment/Weather")
    assert float(weather.find("Fog").get("visualRange")) == 300.0
    assert float(weather.find("Precipitation").get("precipitationIntensity")) == pytest.approx(5.0)
    assert float(weather.find("Sun").get("elevation")) == pytest.approx(np.radians(30.0))


def test_a_follow_speed_profile_is_followingmode_follow_with_its_limits(tmp_path):
    """Exported as SpeedProfileAction followingMode follow with DynamicConstraints; the .xosc
    alone imports back to the same profile (mode, limits); a limit left unset is listed."""
    text = """scenario prof {
  duration 14 s
  road r {
    line length 500 m
    lanes right 1
  }
  ego car on r lane -1 at 100 m speed 10 m/s
  agent a car on r lane -1 at 20 m speed 0 m/s {
    at 2 s behavior speed_profile times [0, 4, 8, 10] s speeds [0, 10, 4, 8] m/s mode follow \\
      accel 5 m/s^2 decel 10 m/s^2 accel_rate 4 m/s^3 decel_rate 3 m/s^3
  }
}
"""
    done = export_run(expand(compile_source(text, "prof.addt").plan).specs[0], tmp_path)
    action = DET.parse(done.xosc_path).getroot().find(".//SpeedProfileAction")
    assert action.get("followingMode") == "follow"
    assert {k: float(v) for k, v in action.find("DynamicConstraints").attrib.items()} == {
        "maxAcceleration": 5.0, "maxDeceleration": 10.0, "maxAccelerationRate": 4.0, "maxDecelerationRate": 3.0}
    assert any("limits left unset" in c for c in done.carried)
    done.sidecar_path.unlink()
    got = import_xosc(done.xosc_path)
    assert got.text is not None, [d.message for d in got.diagnostics]
    clause = next(t.clause for a in got.plan.actors() for t in a.triggers if t.clause.name == "speed_profile")
    assert clause.settings["mode"] == "follow"
    assert {k: clause.settings[k].value for k in ("accel", "decel", "accel_rate", "decel_rate")} == {
        "accel": 5.0, "decel": 10.0, "accel_rate": 4.0, "decel_rate": 3.0}


def test_routes_are_assign_route_actions(tmp_path):
    spec = expand(compile_file(EXAMPLES / "left_turn.addt").plan).specs[0]
    done = export_run(spec, tmp_path)
    root = DET.parse(done.xosc_path).getroot()
    for actor in spec.plan.actors():
        if not actor.route:
            continue
        private = root.find(f"Storyboard/Init/Actions/Private[@entityRef='{actor.name}']")
        roads = [p.get("roadId") for p in private.findall(".//AssignRouteAction/Route/Waypoint/Position/LanePosition")]
        assert roads == list(actor.route), actor.name  # one waypoint per road, connecting road included
    assert not any("no RoutingAction" in line for line in done.carried)
    # The ego starts on road 0's lane 1, driven against s, `at 40 m`: that is the road's
    # station on a route too, so the teleport says s = 40 (it said the road's length less 40).
    teleport = root.find("Storyboard/Init/Actions/Private[@entityRef='ego']//TeleportAction/Position/LanePosition")
    assert (teleport.get("roadId"), teleport.get("laneId"), float(teleport.get("s"))) == ("0", "1", 40.0)


def test_traffic_lights_are_openscenario_signals(tmp_path):
    """Controllers are TrafficSignalControllers (phases green, yellow, red with each signal's
    lamp states), light steps TrafficSignal actions of an actor-less group, `light(C) == S`
    a TrafficSignalCondition; inline signals stand in the generated .xodr; what has no
    OpenSCENARIO form (`at_red run`, a program offset, `state program`) is listed."""
    spec = expand(compile_file(ROOT / "tests" / "data" / "interop" / "every_light.addt").plan).specs[0]
    done = export_run(spec, tmp_path)
    root = DET.parse(done.xosc_path).getroot()
    main_ctl = root.find("RoadNetwork/TrafficSignals/TrafficSignalController[@name='main']")
    phases = [(p.get("name"), float(p.get("duration")), [(s.get("trafficSignalId"), s.get("state"))
                                                         for s in p.iterfind("TrafficSignalState")])
              for p in main_ctl.iterfind("Phase")]
    # green 60 s, yellow 2 s, red 20 s with green from 1 s: at 0 s the cycle is 1 s before
    # the end of its red, so the phases start with that 1 s and end with the other 19 s.
    assert phases == [("red_at_start", 1.0, [("1", "on;off;off"), ("2", "on;off;off")]),
                      ("green", 60.0, [("1", "off;off;on"), ("2", "off;off;on")]),
                      ("yellow", 2.0, [("1", "off;on;off"), ("2", "off;on;off")]),
                      ("red", 19.0, [("1", "on;off;off"), ("2", "on;off;off")])]
    group = root.find(".//ManeuverGroup[@name='addt_lights']")
    assert group.find("Actors/EntityRef") is None
    red = group.find(".//Event[@name='light_main_red']")
    assert [(a.get("name"), a.get("state")) for a in red.iterfind(".//TrafficSignalStateAction")] == \
        [("1", "on;off;off"), ("2", "on;off;off")]
    assert red.find(".//RelativeDistanceCondition") is not None
    program = group.find(".//Event[@name='light_main_program']//TrafficSignalControllerAction")
    assert program.attrib == {"phase": "green", "trafficSignalControllerRef": "main"}
    on_red = group.find(".//Event[@name='light_other_green']")
    assert on_red.find(".//TrafficSignalCondition").attrib == {"name": "1", "state": "on;off;off"}
    parked = root.find(".//Event[@name='parked_cruise']//TrafficSignalCondition")
    assert parked is not None and parked.get("state") == "on;off;off"
    # The generated road has the three signals, numbered, facing their lanes' traffic.
    odr = DET.parse(done.xodr_path).getroot()
    signals = {s.get("name"): s for s in odr.iter("signal")}
    assert {n: (s.get("id"), s.get("orientation"), s.find("validity").get("fromLane"), s.get("type"))
            for n, s in signals.items()} == {"s1": ("1", "+", "-1", "1000001"), "s2": ("2", "+", "-2", "1000001"),
                                             "back": ("3", "-", "1", "1000001")}
    listed = "\n".join(done.carried)
    assert "runner: at_red run" in listed and "offset" not in listed
    assert "light main state program" in listed
    side = json.loads(done.sidecar_path.read_text())
    assert side["actors"]["runner"]["ignore_lights"] is True and side["actors"]["parked"]["ignore_lights"] is False
    assert side["lights"]["controllers"]["main"] == {"green_s": 60.0, "yellow_s": 2.0, "red_s": 20.0, "offset_s": 1.0}
    assert side["lights"]["steps"]["light_main_program"]["settings"]["state"] == "program"


def test_lamp_states_follow_the_signal_type():
    from addt_dsl.interop.xosc_export import lamp_state, lamps_of, state_of_lamps

    car, walk = lamps_of("1000001"), lamps_of("1000002", "-1")
    assert [lamp_state(car, s) for s in ("red", "yellow", "green")] == ["on;off;off", "off;on;off", "off;off;on"]
    assert [lamp_state(walk, s) for s in ("red", "yellow", "green")] == ["on;off", "on;off", "off;on"]
    assert lamps_of("1000009", "20") == ("yellow", "green") and lamps_of("206") == car  # unknown: three lamps
    for lamps in (car, walk):
        for state in ("red", "green"):
            assert state_of_lamps(lamps, lamp_state(lamps, state)) == state
    assert state_of_lamps(car, "off;flashing;off") == "yellow" and state_of_lamps(car, "Amber") == "yellow"
    assert state_of_lamps(car, "on;on;off") is None and state_of_lamps(car, "on;off") is None


def test_exporting_twice_gives_the_same_bytes(tmp_path, monkeypatch):
    path = EXAMPLES / "red_light_runner.addt"
    spec = expand(compile_file(path).plan).specs[0]
    first = export_run(spec, tmp_path / "a", "s")
    second = export_run(spec, tmp_path / "b", "s")
    for name in ("xosc_path", "xodr_path", "sidecar_path"):
        assert getattr(first, name).read_bytes() == getattr(second, name).read_bytes()
    header = DET.parse(first.xosc_path).getroot().find("FileHeader")
    assert header.get("date") == "1970-01-01T00:00:00"
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1764115200")  # 2025-11-26 00:00 UTC
    third = export_run(spec, tmp_path / "c", "s")
    assert DET.parse(third.xosc_path).getroot().find("FileHeader").get("date") == "2025-11-26T00:00:00"


def test_an_inline_roads_xodr_is_the_same_bytes_each_time(tmp_path, monkeypatch):
    """The generated .xodr's header carried the time of writing; it carries the export's
    date (SOURCE_DATE_EPOCH, else the epoch) as the .xosc does."""
    spec = expand(compile_file(ROOT / "tests" / "data" / "interop" / "every_light.addt").plan).specs[0]
    first = export_run(spec, tmp_path / "a", "s")
    second = export_run(spec, tmp_path / "b", "s")
    assert first.xodr_path.read_bytes() == second.xodr_path.read_bytes()
    assert DET.parse(first.xodr_path).getroot().find("header").get("date") == "1970-01-01T00:00:00"
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1764115200")  # 2025-11-26 00:00 UTC
    third = export_run(spec, tmp_path / "c", "s")
    assert DET.parse(third.xodr_path).getroot().find("header").get("date") == "2025-11-26T00:00:00"


@pytest.mark.parametrize(("params", "words"), [
    (["lead_speed=1e308m/s"], "outside lead_speed's range [12 m/s, 22 m/s]"),
    (["lead_speed=-99m/s"], "outside lead_speed's range"),
    (["drop_rate=70%"], "outside drop_rate's range"),
])
def test_cli_export_refuses_values_beyond_a_parameters_range(params, words, tmp_path, capsys):
    """The compiler checks what depends on a parameter over its range only: exported with a
    value beyond it (a lead at 1e308 m/s, or at -99 m/s), the files held a run no scenario
    can state, written with exit 0."""
    assert main(["export", str(EXAMPLES / "lead_brake.addt"), "--params", *params, "--to", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: --params {params[0]}: ") and words in err and "Traceback" not in err
    assert not list(tmp_path.iterdir())


def test_cli_export_checks_a_parameter_without_a_range(tmp_path, capsys):
    (tmp_path / "s.addt").write_text("""scenario norange {
  duration 5 s
  road r {
    line length 400 m
  }
  param v = 10 m/s
  ego car on r lane -1 at 20 m speed 10 m/s
  agent lead car on r lane -1 at 60 m speed v {
    behavior cruise speed v
  }
}
""")
    assert main(["export", str(tmp_path / "s.addt"), "--params", "v=1e308m/s", "--to", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "not a run the scenario can state" in err and "E0301" in err and not (tmp_path / "o").exists()
    assert main(["export", str(tmp_path / "s.addt"), "--params", "v=12m/s", "--to", str(tmp_path / "o")]) == 0


NAMED = """
scenario named {
  duration 8 s
  road main {
    line length 300 m
    lanes right 2
  }
  ego car on main lane -1 at 10 m speed 10 m/s goal 200 m {
    stack bev cruise_speed 10 m/s
  }
  agent lead car on main lane -1 at 50 m speed 10 m/s {
    brake_hard: at 2 s behavior brake decel 4 m/s^2 to_speed 3 m/s
  }
  agent other car on main lane -2 at 30 m speed 10 m/s {
    when %s(lead.brake_hard) then behavior brake decel 3 m/s^2 to_speed 6 m/s
  }
  expect {
    no collision
  }
}
"""


@pytest.mark.parametrize("fn,state", [("ended", "endTransition"), ("started", "startTransition")])
def test_a_named_steps_state_exports_as_its_events_state_and_imports_back(fn, state, tmp_path):
    """`when ended(lead.brake_hard)` is a StoryboardElementStateCondition on the step's event (named
    after the step), not a ParameterCondition that nothing sets; without the side file the import
    names the step again and the condition reads it."""
    from addt_dsl.interop.openscenario.importer import import_xosc

    spec = expand(compile_source(NAMED % fn, "named.addt").plan).specs[0]
    done = export_run(spec, tmp_path, "named")
    root = DET.fromstring(done.xosc_path.read_text())
    assert root.find(".//ParameterCondition") is None
    conds = root.findall(".//StoryboardElementStateCondition")
    assert [(c.get("storyboardElementRef"), c.get("state"), c.get("storyboardElementType")) for c in conds] == [
        ("brake_hard", state, "event")]
    assert root.find(".//Event[@name='brake_hard']") is not None
    assert not any("ParameterCondition" in line for line in done.carried)
    done.sidecar_path.unlink()
    got = import_xosc(done.xosc_path)
    assert got.text is not None, [d.message for d in got.diagnostics]
    assert not [d for d in got.diagnostics if d.code.startswith("E")], [d.message for d in got.diagnostics]
    assert "brake_hard: at 2 s behavior cruise speed 3 m/s accel 4 m/s^2 decel 4 m/s^2" in got.text
    assert f"when {fn}(lead.brake_hard) then behavior" in got.text
    back = tmp_path / "back"
    back.mkdir()
    for name, body in got.side_files.items():
        (back / name).write_text(body)
    result = compile_source(got.text, "named.addt", base_dir=back)
    assert result.ok, [d.message for d in result.diagnostics]
