"""The shrink engine against a synthetic judge: fast, exact, property-based.

The judge stands in for the simulator: a run fails `no_collision` (mode "with lead")
exactly when it has a `stuck control.accel` fault with value >= 1.3 whose window covers
[2 s, 3 s], and parameter `gap` is below 40 m. Everything else is harmless, so the
minimal counterexample is known in closed form.
"""

from __future__ import annotations

from collections import Counter

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from tests.unit.search.search_testkit import concrete_faults, judged, kitchen_sink_plan

from addt_dsl.plan import ConcreteFault, RunSpec
from addt_dsl.search import candidates as C
from addt_dsl.search.cache import RunCache
from addt_dsl.runtime.result import Failure, RunResult
from addt_dsl.search.shrink import NotFailing, Shrinker

CULPRIT_MIN = 1.3


def _culprit(f: ConcreteFault, duration: float) -> bool:
    end = duration if f.end_s is None else f.end_s
    return (f.kind == "stuck" and f.target == "control.accel" and f.settings.get("value", 0.0) >= CULPRIT_MIN
            and f.start_s <= 2.0 and end >= 3.0)


class Judge:
    def __init__(self, mode_of_second_culprit: str | None = None):
        self.calls: Counter = Counter()

    def __call__(self, spec: RunSpec) -> RunResult:
        self.calls[spec.key()] += 1
        fails = any(_culprit(f, spec.plan.duration_s) for f in spec.faults) and spec.params.get("gap", 30.0) < 40.0
        failures = (Failure("no_collision", "clearance(ego) > 0 m [with lead]", 3.0, -0.5),) if fails else ()
        return judged(spec, {"no_collision": -0.5 if fails else 1.0}, failures)


def _spec(faults, gap=30.0) -> RunSpec:
    plan = kitchen_sink_plan()
    params = {**plan.nominal_params(), "gap": gap}
    return RunSpec(plan=plan, params=params, seed=123, faults=faults)


CULPRIT = ConcreteFault(index=0, kind="stuck", target="control.accel", start_s=0.5, end_s=None,
                        settings={"value": 3.0}, seed=7)


def _shrink(spec, budget=400):
    judge = Judge()
    shrinker = Shrinker(spec, nominal_plan=kitchen_sink_plan(), cache=RunCache(evaluator=judge),
                        max_simulations=budget)
    return shrinker.run(), judge


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(concrete_faults(kitchen_sink_plan(), max_faults=9), st.integers(0, 9),
       st.floats(10.0, 39.0))
def test_shrinks_to_the_one_culprit(noise, position, gap):
    noise = [f for f in noise if not _culprit(f, kitchen_sink_plan().duration_s)]
    faults = noise[:position] + [CULPRIT] + noise[position:]
    result, judge = _shrink(_spec(faults, gap))
    assert [(f.kind, f.target) for f in result.best.faults] == [("stuck", "control.accel")]
    f = result.best.faults[0]
    # Minimal: the window is exactly [2 s, 3 s] and the value the threshold (to bisection precision).
    assert f.start_s == pytest.approx(2.0, abs=0.05) and f.end_s == pytest.approx(3.0, abs=0.05)
    assert CULPRIT_MIN <= f.settings["value"] <= CULPRIT_MIN + 0.1
    assert result.best.params["gap"] == 30.0  # back to nominal: the gap did not matter beyond < 40 m
    assert result.target.id == ("no_collision", "clearance(ego) > 0 m [with lead]")
    assert max(judge.calls.values()) == 1, "a candidate was simulated twice"
    assert result.simulations == len(judge.calls)
    assert sum(s.accepted for s in result.stats) >= 1


def test_every_accepted_step_is_simpler_and_the_loop_ends():
    faults = [CULPRIT, CULPRIT.model_copy(update={"kind": "drop", "target": "lidar", "settings": {"rate": 0.5}})]
    judge = Judge()
    shrinker = Shrinker(_spec(faults), nominal_plan=kitchen_sink_plan(), cache=RunCache(evaluator=judge))
    keys = [shrinker.key(shrinker.best)]
    original_consider = shrinker.consider

    def watching(candidate, extra=None):
        accepted = original_consider(candidate, extra)
        if accepted:
            keys.append(shrinker.key(shrinker.best))
        return accepted

    shrinker.consider = watching
    result = shrinker.run()
    assert all(b < a for a, b in zip(keys, keys[1:]))
    assert not result.budget_exhausted


def test_budget_is_respected():
    noise = [CULPRIT.model_copy(update={"kind": "drop", "target": "lidar", "settings": {"rate": 0.1 * i},
                                        "seed": i}) for i in range(8)]
    result, judge = _shrink(_spec(noise + [CULPRIT]), budget=5)
    assert result.simulations <= 5 and result.budget_exhausted
    assert judge.calls.total() <= 6  # the original run plus the budget


def test_deterministic():
    noise = [CULPRIT.model_copy(update={"kind": "drop", "target": "lidar", "settings": {"rate": 0.1 * i},
                                        "seed": i}) for i in range(5)]
    a, _ = _shrink(_spec(noise + [CULPRIT]))
    b, _ = _shrink(_spec(noise + [CULPRIT]))
    assert a.best.key() == b.best.key()
    assert [s.simulations for s in a.stats] == [s.simulations for s in b.stats]


def test_changes_name_what_did_not_matter():
    drop = CULPRIT.model_copy(update={"kind": "drop", "target": "lidar", "settings": {"rate": 0.2}})
    result, _ = _shrink(_spec([drop, CULPRIT], gap=20.0))
    text = "\n".join(result.changes)
    assert "did not matter: fault drop lidar" in text
    assert "reduced: fault stuck control.accel value 3 -> " in text
    assert "did not matter: parameter gap 20 -> 30 (nominal)" in text


def test_agents_no_oracle_needs_are_deleted_with_their_oracles():
    result, _ = _shrink(_spec([CULPRIT]))
    assert [a.name for a in result.best.plan.agents] == []  # the judge needs neither lead nor bike
    assert all("lead" not in o.name for o in result.best.plan.oracles)
    assert "did not matter: agent bike" in result.changes


def test_the_kept_oracle_keeps_its_agents():
    spec = C.pinned(_spec([CULPRIT]))
    assert "lead" not in C.removable_agents(spec, "no_collision_with_lead")
    assert "bike" in C.removable_agents(spec, "no_collision_with_lead")


def test_a_passing_run_is_not_shrunk():
    with pytest.raises(NotFailing):
        Shrinker(_spec([]), cache=RunCache(evaluator=Judge()))


# ---------------------------------------------------------------- bits

def bit_judge(spec: RunSpec) -> RunResult:
    """Fails when a bit flip on control.steer flips bit 55 or higher; with `bit -1` the
    bit comes from the fault's seed (like the real kind draws it from its stream)."""
    flipped, fails = {}, False
    for f in spec.faults:
        if f.kind != "bitflip":
            continue
        bit = int(f.settings.get("bit", -1.0))
        bit = bit if bit >= 0 else 52 + f.seed % 11
        flipped[f.index] = (bit,)
        fails |= f.target == "control.steer" and bit >= 55
    failures = (Failure("lane_keeping", "abs(lane_offset(ego)) < 1.5 m [left]", 2.0, -0.1),) if fails else ()
    return judged(spec, {}, failures, drawn_values=flipped)


def test_bit_flips_get_the_flipped_bit_then_the_lowest_that_still_fails():
    flip = ConcreteFault(index=0, kind="bitflip", target="control.steer", start_s=1.0, end_s=3.0,
                         settings={"count": 4.0, "field": "exponent"}, seed=11019)  # flips bit 60
    assert 52 + flip.seed % 11 >= 55
    shrinker = Shrinker(_spec([flip]), nominal_plan=kitchen_sink_plan(), cache=RunCache(evaluator=bit_judge))
    result = shrinker.run()
    (f,) = result.best.faults
    assert f.settings["bit"] == 55.0  # fixed, then lowered to the least significant failing bit
    assert f.settings.get("count", 1.0) == 1.0
    assert "field" not in f.settings  # irrelevant once the bit is fixed
    assert f.start_s == f.end_s  # one instant is enough for this judge


def test_which_setting_is_drawn_comes_from_the_fault_kind(monkeypatch):
    from addt_dsl.registry import FAULTS

    drawn = {cls.keyword: cls.drawn_setting for cls in FAULTS.classes() if cls.drawn_setting}
    assert drawn == {"bitflip": "bit"}
    for kind, name in drawn.items():
        assert C.drawn_setting(kind) == name and name in {p.name for p in FAULTS.get(kind).params}
    # Without the property the shrinker has nothing to pin: the drawn bit stays drawn.
    monkeypatch.setattr(FAULTS.get("bitflip"), "drawn_setting", None)
    flip = ConcreteFault(index=0, kind="bitflip", target="control.steer", start_s=1.0, end_s=3.0,
                         settings={"count": 4.0, "field": "exponent"}, seed=11019)
    result = Shrinker(_spec([flip]), nominal_plan=kitchen_sink_plan(), cache=RunCache(evaluator=bit_judge)).run()
    assert result.best.faults[0].settings.get("bit", -1.0) < 0


def test_evidence_ends_where_the_formula_stops_looking():
    from addt_dsl import expr as E
    from addt_dsl.search.shrink import evidence_end, horizon

    atom = E.Binary(op=">", left=E.Signal(name="clearance(ego)"), right=E.Num(value=0.0))
    assert evidence_end(E.Temporal(op="always", arg=atom), 4.0) == 4.0
    look_ahead = E.Temporal(op="always", arg=E.Temporal(op="eventually", lo_s=0.0, hi_s=2.0, arg=atom))
    assert evidence_end(look_ahead, 4.0) == 6.0
    assert evidence_end(E.Temporal(op="eventually", arg=atom), 0.0) is None  # reach_goal: the whole run
    assert evidence_end(E.Temporal(op="eventually", hi_s=5.0, arg=atom), 0.0) == 5.0
    assert horizon(E.Until(hi_s=1.0, left=atom, right=E.Temporal(op="always", hi_s=2.0, arg=atom))) == 3.0


def test_evidence_ends_where_the_runs_parameter_window_stops_looking():
    """A window over a parameter looks as far as the run's value makes it (the horizon of
    `eventually within t_look` was `Param + float`: a TypeError)."""
    from addt_dsl.compiler import compile_source
    from addt_dsl.sweep import make_spec

    plan = compile_source("""scenario look {
  duration 10 s
  param t_look = 2 s in [1 s, 4 s]
  road r { line length 400 m }
  ego car on r lane -1 at 20 m speed 10 m/s
  agent lead car on r lane -1 at 60 m speed 10 m/s
  expect {
    w: always eventually within t_look gap(ego, lead) > 5 m
  }
}""", path="look.addt").plan
    spec = make_spec(plan, {**plan.nominal_params(), "t_look": 3.5}, 1)

    def judge(s):
        return judged(s, {"w": -1.0}, (Failure("w", "", 3.0, -1.0),))

    shrinker = Shrinker(spec, nominal_plan=plan, cache=RunCache(evaluator=judge), max_simulations=5)
    assert shrinker.evidence_end() == 6.5
