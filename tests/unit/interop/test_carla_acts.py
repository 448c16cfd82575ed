"""A CARLA file's acts as ScenarioRunner runs them (srunner/scenarios/open_scenario.py,
openscenario_parser.py): an act's start conditions are checked from the story's start and
each counts once it has held (no edges); its events' conditions are checked from the act's
start (their simulation times and the travelled distance of the entity the act started on
count from then); the only act's stop trigger ends the story and the run, its conditions
checked from the act's start, any one enough."""

from __future__ import annotations

from addt_dsl import expr as E
from addt_dsl.compiler import compile_source
from addt_dsl.interop.openscenario.importer import import_xosc
from tests.conftest import ROOT

CARLA = ROOT / "tests" / "data" / "carla"


def _plan(name: str, tmp_path):
    got = import_xosc(CARLA / "xosc" / name, maps=[CARLA / "maps"], lenient=True)
    for file, body in got.side_files.items():
        (tmp_path / file).write_text(body)
    result = compile_source(got.text, "imported.addt", base_dir=tmp_path)
    assert result.ok, [d.message for d in result.diagnostics]
    return got, result.plan


def _errors(name: str) -> list[str]:
    got = import_xosc(CARLA / "xosc" / name, maps=[CARLA / "maps"])
    return [d.message for d in got.diagnostics if d.is_error]


def _value(expr) -> float:
    return float(E.eval_param_expr(expr, {}))


def test_act_start_and_stop_translate_where_they_were_refused():
    # Before, every act start condition but a time, and every act stop, was E0803; the
    # criteria that were left (WrongLaneTest, OnSidewalkTest) translate now too.
    assert _errors("FollowLeadingVehicle.xosc") == []
    assert _errors("Slalom.xosc") == []


def test_an_act_on_a_travelled_distance_starts_each_event_on_it_and_its_stop_ends_the_run(tmp_path):
    # FollowLeadingVehicle: the act starts once the hero has travelled 1 m (with `time ==
    # 0`, true at the first tick and kept: ScenarioRunner's one-shot conditions), and stops
    # when it has travelled 200 m more; its first event waits for the adversary within 40 m.
    got, plan = _plan("FollowLeadingVehicle.xosc", tmp_path)
    s0 = _value(plan.ego.s)
    first = next(a for a in plan.agents if a.name == "adversary").triggers[0]
    act, own = first.condition.left, first.condition.right
    assert act == E.Binary(op=">=", left=E.Signal(name="s(ego)"), right=E.Num(value=s0 + 1.0))
    assert "gap(ego,adversary)" in str(own) and first.edge is None  # (ScenarioRunner reads no edges)
    assert plan.end.condition == E.Binary(op=">=", left=E.Signal(name="s(ego)"), right=E.Num(value=s0 + 201.0))
    assert any("counted from the act's start threshold" in d.message for d in got.diagnostics)


def test_an_act_whose_events_count_time_from_its_start_is_a_group_armed_then(tmp_path):
    # IntersectionCollisionAvoidance: the act starts when the hero has travelled 0.1 m; its
    # events start 0.1 s after that (SimulationTimeCondition 0.1 in each event): `after`,
    # counted from the group's start, not `at 0.1 s` of the run.
    _, plan = _plan("IntersectionCollisionAvoidance.xosc", tmp_path)
    group = next(a for a in plan.agents if a.name == "adversary").triggers[0]
    assert group.label == "Behavior" and group.group.mode == "parallel"
    start = group.condition.right  # (the hero's station from its start, in its route's frame) + 0.1 m
    assert group.condition.left == E.Signal(name="s(ego)") and start.op == "+" and start.right == E.Num(value=0.1)
    assert [_value(s.after_s) for s in group.group.steps] == [0.1] * len(group.group.steps)
    assert all(s.at_s is None for s in group.group.steps)


def test_times_count_from_the_act_start_and_a_time_stop_is_the_duration(tmp_path):
    # ChangingWeather: the act starts after 5 s, its weather event 20 s after that: 25 s.
    _, plan = _plan("ChangingWeather.xosc", tmp_path)
    assert {_value(s.at_s) for s in plan.environment_steps} == {25.0}
    # Slalom: the act starts after 120 s; its stop (120 s, delay 1 s) is checked from
    # then: 120 + 1 + 120 = 241 s, where ScenarioRunner's story, and the run, end.
    _, plan = _plan("Slalom.xosc", tmp_path)
    assert plan.duration_s == 241.0
