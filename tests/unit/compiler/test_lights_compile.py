"""`lights { }` compiles to plan data: inline signals, controllers with their programs, light steps."""

from pathlib import Path

from addt_dsl import expr as E
from addt_dsl.compiler import compile_source
from addt_dsl.plan import LIGHT_STATES

EXAMPLES = Path(__file__).resolve().parents[3] / "examples"

SOURCE = """
scenario lit {
  duration 20 s
  road r {
    line length 300 m
    lanes right 2 left 1
  }
  param red_time = 12 s in [8 s, 16 s]
  lights {
    signal s1 road r at 150 m lane -1
    signal s2 at 150 m
    controller main signals [s1, s2] green 8 s red red_time offset 2 s
    at 5 s light main state red
    when distance(ego, car1) < 30 m then light main state program
  }
  ego car on r lane -1 at 10 m speed 10 m/s
  agent car1 car on r lane -2 at 20 m speed 10 m/s at_red run
  expect {
    no red_light
    always light(main) == yellow implies speed(ego) > 0 m/s
  }
}
"""


def test_inline_signals_controllers_and_steps_lower_to_plan_data():
    result = compile_source(SOURCE, "lit.addt")
    assert result.ok, [str(d) for d in result.diagnostics]
    plan = result.plan
    assert [(s.name, s.road, s.s_m, s.lanes) for s in plan.signals] == [("s1", "r", 150.0, [-1]),
                                                                         ("s2", "r", 150.0, [])]
    (c,) = plan.controllers
    assert (c.name, c.road, c.signals) == ("main", "r", ["s1", "s2"])
    assert (c.green_s, c.yellow_s, c.red_s, c.offset_s) == (E.Num(value=8.0), E.Num(value=3.0),
                                                            E.Param(name="red_time"), E.Num(value=2.0))
    first, second = plan.light_steps
    assert first.at_s == E.Num(value=5.0) and first.clause.settings == {"state": "red"}
    assert second.condition is not None and second.clause.settings == {"state": "program"}
    assert [a.ignore_lights for a in plan.actors()] == [False, True]
    oracles = {o.name: o for o in plan.oracles}
    assert E.signals_used(oracles["no_red_light"].formula) == {"red_light(ego)"}
    yellow = next(o for o in plan.oracles if o.name != "no_red_light").formula
    assert E.Num(value=LIGHT_STATES["yellow"]) in list(E.walk(yellow))


def test_map_signals_are_the_controllers_signals():
    source = """scenario lit {
  duration 10 s
  road town import "maps/fabriksgatan_traffic_lights.xodr" road 3
  lights {
    controller west signals [1, 2, 3]
  }
  ego car on town lane -1 at 20 m
}
"""
    plan = compile_source(source, "lit.addt", base_dir=EXAMPLES).plan
    assert plan.controllers[0].signals == ["1", "2", "3"] and plan.signals == []


def test_scenarios_without_lights_have_empty_light_data():
    plan = compile_source("scenario s {\n  duration 5 s\n  road r { line length 100 m }\n"
                          "  ego car on r lane -1 at 10 m\n}\n", "s.addt").plan
    assert plan.signals == [] and plan.controllers == [] and plan.light_steps == []
