"""Routes and driving direction in the compiler: expansion, relative placement along the
other actor's direction and route, lanes checked where an actor starts."""

from __future__ import annotations

from pathlib import Path

from addt_dsl.compiler import compile_source
from addt_dsl.expr import eval_param_expr

EXAMPLES = Path(__file__).resolve().parents[3] / "examples"


def _plan(body: str):
    result = compile_source("scenario s {\n  duration 10 s\n" + body + "\n}\n", "s.addt", base_dir=EXAMPLES)
    assert result.ok, [str(d) for d in result.diagnostics]
    return result.plan


def test_turns_and_named_roads_expand_to_the_same_route():
    a = _plan('  road town import "maps/fabriksgatan.xodr" road 0\n'
              "  ego car on town route 0 -> left lane 1 at 40 m")
    b = _plan('  road town import "maps/fabriksgatan.xodr" road 0\n'
              "  ego car on town route 0 -> 3 lane 1 at 40 m")
    assert a.ego.route == b.ego.route == ["0", "10", "3"]


def test_ahead_follows_the_other_actors_direction():
    plan = _plan("  road r {\n    line length 400 m\n    lanes right 1 left 1\n  }\n"
                 "  ego car on r lane -1 at 100 m\n"
                 "  agent along car ahead of ego 20 m\n"
                 "  agent oncoming car on r lane 1 at 300 m\n"
                 "  agent before_it car ahead of oncoming 20 m")
    s = {a.name: eval_param_expr(a.s, {}) for a in plan.actors()}
    assert s["along"] == 100 + 20 + 4.6
    assert s["before_it"] == 300 - 20 - 4.6  # lane 1 is driven against s: ahead is towards s = 0


def test_an_actor_placed_relative_to_one_on_a_route_shares_it():
    plan = _plan('  road town import "maps/fabriksgatan.xodr" road 0\n'
                 "  ego car on town route 0 -> left lane 1 at 60 m\n"
                 "  agent lead car ahead of ego 10 m")
    lead = plan.agents[0]
    assert lead.route == ["0", "10", "3"] and eval_param_expr(lead.s, {}) == 60 - 10 - 4.6


def test_lanes_are_checked_where_the_actor_starts():
    # two_plus_one.xodr: lane -2 exists from s = 125 m only.
    ok = compile_source('scenario s {\n  duration 5 s\n  road r import "maps/two_plus_one.xodr"\n'
                        "  ego car on r lane -2 at 200 m\n}\n", "s.addt", base_dir=EXAMPLES)
    assert ok.ok, [str(d) for d in ok.diagnostics]
    bad = compile_source('scenario s {\n  duration 5 s\n  road r import "maps/two_plus_one.xodr"\n'
                         "  ego car on r lane -2 at 20 m\n}\n", "s.addt", base_dir=EXAMPLES)
    assert [d.code for d in bad.diagnostics] == ["E0301"]
