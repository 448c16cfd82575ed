"""Agent scripts: steps fire once, sequences wait for the previous step to be done,
parallel groups arm together. Checked against a direct computation of firing times."""

from __future__ import annotations

import itertools
import math

from hypothesis import given, settings
from hypothesis import strategies as st

from addt_dsl.expr import Binary, Num, Param, Signal
from addt_dsl.plan import ClausePlan, GroupPlan, TriggerPlan
from addt_dsl.runtime.bound import bind_step
from addt_dsl.runtime.script import Script

DT = 0.1


def clause(name: str) -> ClausePlan:
    return ClausePlan(keyword="behavior", name=name, settings={})


def run(triggers, duration=20.0, holds=lambda cond: True, params=None):
    script = Script(tuple(bind_step(t, params or {}) for t in triggers))
    started: list[tuple[str, float]] = []
    for k in range(int(round(duration / DT)) + 1):
        t = k * DT
        script.advance(t, holds, lambda c, time_s: started.append((c.name, round(time_s, 6))))
    return started, script


def test_at_fires_once_at_the_first_step_after_the_time():
    started, script = run([TriggerPlan(at_s=Num(value=2.05), clause=clause("brake"))])
    assert started == [("brake", 2.1)]
    assert script.done


def test_parameters_are_bound_per_run():
    started, _ = run([TriggerPlan(at_s=Param(name="t0"), clause=clause("brake"))], params={"t0": 3.0})
    assert started == [("brake", 3.0)]


def test_sequence_waits_for_the_previous_step_then_after():
    seq = GroupPlan(mode="sequence", steps=[
        TriggerPlan(at_s=Num(value=1.0), clause=clause("a")),
        TriggerPlan(after_s=Num(value=2.0), clause=clause("b")),
        TriggerPlan(clause=clause("c")),
    ])
    started, _ = run([TriggerPlan(group=seq)])
    assert started == [("a", 1.0), ("b", 3.0), ("c", 3.0)]


def test_parallel_arms_together_and_a_sequence_waits_for_all_of_it():
    par = GroupPlan(mode="parallel", steps=[
        TriggerPlan(after_s=Num(value=1.0), clause=clause("a")),
        TriggerPlan(after_s=Num(value=4.0), clause=clause("b")),
    ])
    seq = GroupPlan(mode="sequence", steps=[TriggerPlan(group=par),
                                            TriggerPlan(after_s=Num(value=0.5), clause=clause("c"))])
    started, _ = run([TriggerPlan(at_s=Num(value=2.0), group=seq)])
    assert started == [("a", 3.0), ("b", 6.0), ("c", 6.5)]


def test_condition_gates_firing_and_is_checked_only_when_armed():
    cond = Binary(op="<", left=Signal(name="gap(ego,a)"), right=Num(value=10.0))
    checked: list[float] = []
    now = {"t": 0.0}

    def holds(c):
        checked.append(now["t"])
        return now["t"] >= 5.0

    script = Script((bind_step(TriggerPlan(at_s=Num(value=3.0), condition=cond, clause=clause("brake")), {}),))
    started = []
    for k in range(100):
        now["t"] = k * DT
        script.advance(now["t"], holds, lambda c, t: started.append((c.name, round(t, 6))))
    assert started == [("brake", 5.0)]
    assert min(checked) >= 3.0 - 1e-9 and max(checked) <= 5.0 + 1e-9


# ---------------------------------------------------------------- property

def _steps(depth: int):
    leaf = st.builds(lambda at, after, name: TriggerPlan(
        at_s=None if at is None else Num(value=at), after_s=None if after is None else Num(value=after),
        clause=clause(name)),
        st.none() | st.sampled_from([0.0, 0.5, 1.0, 2.5, 7.0]),
        st.none() | st.sampled_from([0.0, 0.3, 1.0, 2.0]),
        st.sampled_from("abcdefgh"))
    if depth == 0:
        return leaf
    group = st.builds(lambda mode, steps, after: TriggerPlan(
        after_s=None if after is None else Num(value=after), group=GroupPlan(mode=mode, steps=steps)),
        st.sampled_from(["sequence", "parallel"]), st.lists(_steps(depth - 1), min_size=1, max_size=3),
        st.none() | st.sampled_from([0.0, 1.0]))
    return leaf | group


def _tick(t: float) -> float:
    """The first physics step at or after t."""
    return math.ceil(t / DT - 1e-6) * DT


def _expected(step: TriggerPlan, armed: float, out: list) -> float:
    """Fire times appended to `out`; returns the time the step is done."""
    earliest = armed + (step.after_s.value if step.after_s else 0.0)
    if step.at_s is not None:
        earliest = max(earliest, step.at_s.value)
    fired = _tick(earliest)
    if step.clause is not None:
        out.append((step.clause.name, round(fired, 6)))
    if step.group is None:
        return fired
    if step.group.mode == "parallel":
        return max(_expected(s, fired, out) for s in step.group.steps)
    t = fired
    for s in step.group.steps:
        t = _expected(s, t, out)
    return t


@settings(max_examples=200, deadline=None)
@given(st.lists(_steps(2), min_size=1, max_size=4))
def test_firing_times_match_the_semantics(triggers):
    expected: list = []
    for trig in triggers:
        _expected(trig, 0.0, expected)
    horizon = 40.0
    started, script = run(triggers, duration=horizon)
    assert sorted(started) == sorted(e for e in expected if e[1] <= horizon + 1e-9)


@given(st.lists(st.booleans(), min_size=1, max_size=60), st.sampled_from([0.0, 0.1, 0.5, 1.0]))
def test_a_held_condition_fires_after_an_unbroken_run_of_its_duration(samples, hold):
    """`when C for D` fires at the first step where C held at every step of the last D
    seconds: a direct scan of the samples says when."""
    cond = Binary(op="<", left=Signal(name="speed(ego)"), right=Num(value=0.1))
    index = {"k": 0}
    script = Script((bind_step(TriggerPlan(condition=cond, hold_s=Num(value=hold), clause=clause("go")), {}),))
    started = []
    for k, _ in enumerate(samples):
        index["k"] = k
        script.advance(k * DT, lambda c: samples[index["k"]], lambda c, t: started.append(round(t, 6)))
    need = int(round(hold / DT)) + 1  # samples in an unbroken run of `hold` seconds
    run_len, expected = 0, None
    for k, value in enumerate(samples):
        run_len = run_len + 1 if value else 0
        if run_len >= need:
            expected = round(k * DT, 6)
            break
    assert started == ([] if expected is None else [expected])


def test_repeating_steps_rearm_before_another_fires_in_the_same_step():
    # esmini's drive_when_close: `go` and `stop` repeat on rising conditions that take turns
    # every 4 s from 6 s; each behaviour lasts 4 s unless a later one replaces it. At 14 s the stop's
    # behaviour has just ended and the go condition rises: the stop step must be back in
    # standby first (before, `go` fired first and replaced it: `stop` never re-armed and
    # its condition's rise at 18 s was lost).
    clock = {"t": 0.0}
    current: dict[str, object] = {}

    def holds(cond):  # go from 6 to 10 s, stop from 10 to 14 s, go from 14 s, ...
        k = math.floor((clock["t"] - 6.0) / 4.0 + 1e-9)
        return k >= 0 and (k % 2 == 0) == (cond.name == "go")

    def start(c, time_s):
        started.append((c.name, round(time_s, 6)))
        current["beh"] = beh = (c.name, time_s)
        return beh

    def ended(beh, time_s):
        return current.get("beh") is beh and time_s + 1e-9 >= beh[1] + 4.0

    steps = [TriggerPlan(condition=Signal(name=name), edge="rising", repeat=100, clause=clause(name))
             for name in ("go", "stop")]
    script = Script(tuple(bind_step(t, {}) for t in steps))
    started: list[tuple[str, float]] = []
    for k in range(int(round(23.0 / DT)) + 1):
        clock["t"] = k * DT
        script.advance(clock["t"], holds, start, ended)
    assert started == [("go", 6.0), ("stop", 10.0), ("go", 14.0), ("stop", 18.0), ("go", 22.0)]


def _cond(i: int) -> Binary:
    return Binary(op=">", left=Signal(name="s(lead)"), right=Num(value=float(i)))


steps = st.recursive(
    st.builds(lambda i, at, after, has: TriggerPlan(condition=_cond(i) if has else None, clause=clause(f"b{i}"),
                                                    at_s=None if at is None else Num(value=at),
                                                    after_s=None if after is None else Num(value=after)),
              st.integers(0, 30), st.one_of(st.none(), st.floats(0.0, 3.0)), st.one_of(st.none(), st.floats(0.0, 2.0)),
              st.booleans()),
    lambda inner: st.builds(lambda mode, ss, i, has: TriggerPlan(condition=_cond(i) if has else None,
                                                                 group=GroupPlan(mode=mode, steps=ss)),
                            st.sampled_from(["sequence", "parallel"]), st.lists(inner, min_size=1, max_size=3),
                            st.integers(0, 30), st.booleans()),
    max_leaves=6)


@settings(max_examples=80, deadline=None)
@given(st.lists(steps, min_size=1, max_size=3), st.lists(st.booleans(), min_size=1, max_size=50))
def test_a_script_asks_at_least_the_conditions_it_said_it_would(triggers, answers):
    """`Script.asks(t)` before each `advance(t)`: every condition it names, advance asks
    (answered in order from `answers`); advance asks more only of steps it armed or
    re-armed in that same call."""
    script = Script(tuple(bind_step(t, {}) for t in triggers))
    given_answers = itertools.cycle(answers)
    for k in range(40):
        t = k * DT
        said = list(script.asks(t))
        asked = []

        def holds(cond):
            asked.append(cond)
            return next(given_answers)

        script.advance(t, holds, lambda c, time_s: None)
        assert all(any(a is c for a in asked) for c in said)
        assert [c for c in asked if any(c is s for s in said)] == [c for c in said]  # (in advance's order)
