"""`addtc import` of CARLA ScenarioRunner's OpenSCENARIO examples: towns named without a
file extension (found with `--maps`), CARLA's left-handed frame (the "CARLA:" header),
and ScenarioRunner's `criteria_*` test criteria as oracles."""

from __future__ import annotations

import math

import pytest

from addt_dsl.cli import main
from addt_dsl.compiler import compile_source
from addt_dsl.expr import eval_param_expr
from addt_dsl.interop.openscenario.importer import import_xosc
from addt_dsl.road import parse_xodr
from tests.conftest import ROOT

CARLA = ROOT / "tests" / "data" / "carla"
MAPS = CARLA / "maps"
SCENARIOS = sorted((CARLA / "xosc").glob("*.xosc"))
CRITERIA = {"no_red_light", "no_stop_sign", "keep_lane", "no_collision", "driven_distance", "wrong_lane", "on_sidewalk"}


def _import(name: str):
    return import_xosc(CARLA / "xosc" / name, maps=[MAPS], lenient=True)


@pytest.mark.parametrize("path", SCENARIOS, ids=[p.name for p in SCENARIOS])
def test_every_carla_example_imports_and_compiles(path, tmp_path):
    got = import_xosc(path, maps=[MAPS], lenient=True)
    assert not [d for d in got.diagnostics if d.is_error], [d.message for d in got.diagnostics if d.is_error]
    notes = [d.message for d in got.diagnostics if d.code == "W0803"]
    assert any("CARLA's coordinate frame" in m for m in notes) and any("read from" in m for m in notes), notes
    for name, body in got.side_files.items():
        (tmp_path / name).write_text(body)
    result = compile_source(got.text, "imported.addt", base_dir=tmp_path)
    assert result.ok, [d.message for d in result.diagnostics]
    names = {o.name for o in result.plan.oracles}
    # ChangingWeather has no criteria: the import's default oracle.
    assert names == ({"no_collision"} if path.name == "ChangingWeather.xosc" else CRITERIA), names


def _world(plan, actor):
    """Where the plan puts an actor: (x, y) [m] in OpenDRIVE's frame."""
    road = next(r for r in plan.roads if r.name == actor.road)
    odr = parse_xodr(road.xodr_text, road.xodr_file).road(road.xodr_road_id)
    s = float(eval_param_expr(actor.s, {}))
    lane = int(actor.lane.value)  # `at` is the first road's station, on a route too
    # `offset` is to the driver's left: against the road's t on a lane driven against s
    way = odr.travel_direction(lane) * (-1 if actor.reverse else 1)
    t = float(odr.lane_center_t(lane, s)) + way * float(eval_param_expr(actor.offset, {}))
    x, y = odr.point_at(s, t)
    return float(x), float(y)


def test_world_positions_are_mirrored_out_of_carlas_frame():
    # CyclistCrossing's hero: <WorldPosition x="130" y="55" h="pi"/> in CARLA's frame is
    # (130, -55) in the map's. Read as OpenDRIVE coordinates it lay 22 m off any lane.
    plan = _import("CyclistCrossing.xosc").plan
    x, y = _world(plan, plan.ego)
    assert math.hypot(x - 130.0, y + 55.0) < 0.5, (x, y)
    # Facing -x (h = pi): placed on the lane driven that way.
    road = next(r for r in plan.roads if r.name == plan.ego.road)
    odr = parse_xodr(road.xodr_text, road.xodr_file).road(road.xodr_road_id)
    s = float(eval_param_expr(plan.ego.s, {}))
    heading = float(odr.reference_pose(s)[2]) + (0.0 if odr.travel_direction(int(plan.ego.lane.value)) > 0 else math.pi)
    assert math.cos(heading - math.pi) > 0.9


def test_road_offsets_grow_to_the_right_in_carlas_frame():
    # FollowLeadingVehicle: the hero at <RoadPosition roadId="4" s="48.58" t="2.75"/>, the
    # file's comment giving the same place as lane -1 with offset 1.0: 1 m right of lane
    # -1's centre (t = -2 m), so t = -2.75 m in OpenDRIVE's frame. The adversary is
    # <RelativeRoadPosition ds="50" dt="-1.0"/> from it: 1 m to the left.
    plan = _import("FollowLeadingVehicle.xosc").plan
    ego, lead = plan.ego, plan.agents[0]
    assert (ego.lane.value, ego.s.value, ego.offset.value) == (-1.0, 48.58, -0.75)
    assert (lead.lane.value, lead.s.value, lead.offset.value) == (-1.0, pytest.approx(98.58), 0.25)


def test_criteria_become_oracles_and_the_rest_say_why_not():
    got = _import("FollowLeadingVehicle.xosc")
    oracles = {o.name: o for o in got.plan.oracles}
    assert "eventually travelled(ego) >= 100 m" in got.text
    assert oracles["driven_distance"].formula.arg.right.value == 100.0
    skipped = sorted(d.message.split(" ")[0] for d in got.diagnostics if d.code == "W0801"
                     and d.message.startswith("criteria_"))
    assert skipped == []
    # WrongLaneTest and OnSidewalkTest: the lane states of the ego, each saying how it differs.
    assert "always not wrong_way(ego)" in got.text and "always not off_lanes(ego)" in got.text
    notes = {d.message.split(" ")[0]: d.message for d in got.diagnostics if d.code == "W0802"}
    assert "150 deg" in notes["criteria_WrongLaneTest"] and "120 deg" in notes["criteria_WrongLaneTest"]
    assert "second tick" in notes["criteria_OnSidewalkTest"]
    assert "CARLA ScenarioRunner's criteria_*" in got.text
    # RunningStopTest: the map's stop signs (Town01's OpenDRIVE has none: it holds trivially).
    assert oracles["no_stop_sign"].text == "no stop_sign" and "no stop_sign" in got.text
    assert any(d.code == "W0802" and d.message.startswith("criteria_RunningStopTest") for d in got.diagnostics)
    # RunningRedLightTest: the file declares no light controllers, so no light runs (said).
    assert any(d.code == "W0802" and d.message.startswith("criteria_RunningRedLightTest") and "declares none"
               in d.message for d in got.diagnostics)


def test_on_sidewalk_with_a_duration_and_strict_imports(tmp_path):
    # OnSidewalkTest takes the value as its duration only where the condition names a
    # parameterRef (ScenarioRunner's openscenario_parser); 2 s off the lanes in one stretch fail.
    text = (CARLA / "xosc" / "FollowLeadingVehicle.xosc").read_text()
    head, tail = text.split('<Condition name="criteria_OnSidewalkTest"')
    tail = tail.replace('parameterRef="" value=""', 'parameterRef="duration" value="2"', 1)
    (tmp_path / "Timed.xosc").write_text(head + '<Condition name="criteria_OnSidewalkTest"' + tail)
    got = import_xosc(tmp_path / "Timed.xosc", maps=[MAPS], lenient=True)
    oracle = next(o for o in got.plan.oracles if o.name == "on_sidewalk")
    assert oracle.formula.arg.arg.hi_s == 2.0 and "always not (always within 2 s off_lanes(ego))" in got.text
    assert any(d.code == "W0802" and "sums the stretches" in d.message for d in got.diagnostics)
    for name, body in got.side_files.items():
        (tmp_path / name).write_text(body)
    assert compile_source(got.text, "timed.addt", base_dir=tmp_path).ok
    # Both examples that named only these two among what does not translate import strictly.
    for name in ("FollowLeadingVehicle.xosc", "LaneChangeSimple.xosc"):
        strict = import_xosc(CARLA / "xosc" / name, maps=[MAPS])
        assert strict.text is not None, [d.message for d in strict.diagnostics if d.is_error]


def test_a_town_not_found_names_where_it_looked(tmp_path, capsys):
    got = import_xosc(CARLA / "xosc" / "Slalom.xosc")
    errors = [d for d in got.diagnostics if d.is_error]
    assert got.text is None and [d.code for d in errors] == ["E0401"]
    assert "cannot find the road network 'Town01'" in errors[0].message
    assert any("Town01.xodr" in n for n in errors[0].notes) and any("--maps DIR" in n for n in errors[0].notes)
    # The command line: --maps finds it, and the map is written beside the scenario.
    out = tmp_path / "slalom.addt"
    assert main(["import", str(CARLA / "xosc" / "Slalom.xosc"), "--maps", str(MAPS), "--lenient", "-o", str(out)]) == 0
    assert (tmp_path / "Town01.xodr").is_file() and "Town01.xodr" in out.read_text()


def test_a_standing_ego_cruises_at_its_roads_speed_limit():
    # Town01's roads give <type><speed max="25" unit="mph"/>: 11.176 m/s, not the stack's
    # default. Where the map gives none (a junction's connecting road), the default stays.
    got = _import("FollowLeadingVehicle.xosc")
    road = next(r for r in got.plan.roads if r.name == got.plan.ego.road)
    assert parse_xodr(road.xodr_text, road.xodr_file).road(road.xodr_road_id).speed_limit(48.58) == \
        pytest.approx(25 * 0.44704)
    assert got.plan.ego.stack.settings["cruise_speed"].value == pytest.approx(11.176)
    assert any("speed limit, 40.23 km/h" in d.message for d in got.diagnostics)
    assert "cruise_speed" not in _import("SyncArrivalIntersection.xosc").plan.ego.stack.settings


def test_an_ego_without_a_route_drives_on_straight_through_junctions():
    # CyclistCrossing's hero stands on Town01's road 9, 43.6 m long: without a route it left
    # the map at 4.8 s (a left_road event). Straight on, at 25 mph for the run's 60 s.
    got = _import("CyclistCrossing.xosc")
    route = got.plan.ego.route
    assert route[0] == "9" and len(route) >= 3, route
    assert any(d.code == "W0802" and "no route in the file" in d.message for d in got.diagnostics)
    # A road met twice ends the route: it never loops.
    assert len(set(route)) == len(route)


def _body_heading(plan, actor) -> float:
    """The world heading [rad] the plan gives an actor at its place: its lane's driving
    direction (turned round for `reverse`) plus its `yaw`, from the map, not the runtime."""
    road = next(r for r in plan.roads if r.name == actor.road)
    odr = parse_xodr(road.xodr_text, road.xodr_file).road(road.xodr_road_id)
    s = float(eval_param_expr(actor.s, {}))
    way = odr.travel_direction(int(actor.lane.value)) * (-1 if actor.reverse else 1)
    yaw = float(eval_param_expr(actor.yaw, {})) if actor.yaw is not None else 0.0
    return float(odr.reference_pose(s)[2]) + (0.0 if way > 0 else math.pi) + yaw


def test_slaloms_containers_keep_their_world_headings():
    # Slalom places c1, c2 along the road (h = -pi/2, pi/2 in CARLA's frame: +pi/2, -pi/2 in
    # the map's) and c3-c5 across it (h = 0). Imported, each stood facing its lane's way:
    # c1 and c2 turned round, c3-c5 along the road.
    plan = _import("Slalom.xosc").plan
    want = {"c1": math.pi / 2, "c2": -math.pi / 2, "c3": 0.0, "c4": 0.0, "c5": 0.0}
    got = {a.name: _body_heading(plan, a) for a in plan.agents}
    off = {n: abs(math.remainder(got[n] - h, 2 * math.pi)) for n, h in want.items()}
    assert max(off.values()) < 1e-9, got
    # The hero faces where the file says (-pi/2 in CARLA's frame), not its lane's 1.5e-4 rad off it.
    assert abs(math.remainder(_body_heading(plan, plan.ego) - math.pi / 2, 2 * math.pi)) < 1e-9


def _speed_clauses(got, who: str):
    actor = next(a for a in got.plan.agents if a.name == who)
    return [c for c in [*actor.behaviors, *[t.clause for t in actor.triggers if t.clause is not None]]
            if c.name in ("walk", "cruise", "brake")]


def test_a_walker_or_a_longitudinal_only_controller_walks_along_the_files_heading(tmp_path):
    # ScenarioRunner moves a walker (PedestrianControl, its default) and an entity under
    # vehicle_longitudinal_control (no steering) along its body heading; the target speed at
    # once, the action complete after its distance or time.
    for name in ("CyclistCrossing.xosc", "PedestrianCrossingFront.xosc"):
        got = _import(name)
        adversary = next(a for a in got.plan.agents if a.name == "adversary")
        clauses = _speed_clauses(got, "adversary")
        assert clauses and {c.name for c in clauses} == {"walk"}, name
        first = clauses[0].settings
        assert float(eval_param_expr(first["heading"], {})) == float(eval_param_expr(adversary.yaw, {}))
        assert float(eval_param_expr(first["distance"], {})) == 1.5
        assert "duration" not in first and float(eval_param_expr(first["accel"], {})) >= 1000.0
    # The same cyclist under a vehicle's lane-following controller keeps to its lane.
    text = (CARLA / "xosc" / "CyclistCrossing.xosc").read_text().replace(
        '"vehicle_longitudinal_control"', '"npc_vehicle_control"')
    (tmp_path / "Lanes.xosc").write_text(text)
    got = import_xosc(tmp_path / "Lanes.xosc", maps=[MAPS], lenient=True)
    assert {c.name for c in _speed_clauses(got, "adversary")} == {"cruise"}
    # Faster than a `walk` goes: along its lane, said so.
    (tmp_path / "Fast.xosc").write_text((CARLA / "xosc" / "CyclistCrossing.xosc").read_text().replace(
        '<AbsoluteTargetSpeed value="2.0"/>', '<AbsoluteTargetSpeed value="20.0"/>'))
    got = import_xosc(tmp_path / "Fast.xosc", maps=[MAPS], lenient=True)
    assert {c.name for c in _speed_clauses(got, "adversary")} == {"cruise"}
    assert any(d.code == "W0802" and "moves along its lane" in d.message for d in got.diagnostics)


def test_a_criterion_value_without_a_parameter_ref_is_no_argument(tmp_path):
    # ScenarioRunner passes a criterion's value only as the argument its parameterRef names:
    # DrivenDistanceTest with value="100" and no parameterRef has no distance (not translated,
    # said), as OnSidewalkTest's value without one is no duration.
    text = (CARLA / "xosc" / "FollowLeadingVehicle.xosc").read_text()
    assert 'parameterRef="distance_success" value="100"' in text
    (tmp_path / "NoRef.xosc").write_text(text.replace('parameterRef="distance_success" value="100"',
                                                      'parameterRef="" value="100"', 1))
    got = import_xosc(tmp_path / "NoRef.xosc", maps=[MAPS], lenient=True)
    assert "driven_distance" not in {o.name for o in got.plan.oracles}
    assert any(d.message.startswith("criteria_DrivenDistanceTest is not translated") and "parameterRef" in d.message
               for d in got.diagnostics)
