"""Binding a RunSpec evaluates every parameter expression once: the twin reads numbers."""

from __future__ import annotations

from addt_dsl import expr as E
from addt_dsl.compiler import compile_file
from addt_dsl.runtime.bound import bind
from addt_dsl.sweep import expand
from tests.conftest import EXAMPLES


def test_a_bound_scenario_holds_numbers_and_parameter_free_formulas():
    spec = expand(compile_file(EXAMPLES / "lead_brake.addt").plan).specs[0]
    p = {**spec.params, "lead_speed": 18.0, "start_gap": 25.0, "brake_at": 90.0, "decel": 6.0, "headway": 1.2}
    bound = bind(spec.model_copy(update={"params": p}))
    ego, lead = bound.ego, bound.agents[0]
    assert (ego.lane, ego.s, ego.speed, ego.offset, ego.mu) == (-1, 10.0, 18.0, 0.0, 0.8)
    assert (lead.s, lead.speed) == (35.0, 18.0)
    assert ego.stack.settings["time_gap"] == 1.2 and lead.behaviors[0].settings["speed"] == 18.0
    [step] = lead.steps
    assert step.clause.settings["decel"] == 6.0 and step.after_s == 0.0 and step.at_s is None
    formulas = [step.condition] + [o.formula for o in bound.oracles]
    assert not [n for f in formulas for n in E.walk(f) if isinstance(n, E.Param)]
    assert "90" in repr(step.condition)
    assert bound.faults == tuple(spec.faults)
