"""Trigger conditions and live settings read a reused one-sample snapshot of the record
(`triggers.Conditions`): at every sample it must say what the whole trace says there."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from addt_dsl.expr import Binary, Num, Signal
from addt_dsl.runtime import oracles
from addt_dsl.runtime.phases import FIELDS
from addt_dsl.runtime.signals import compute_signals
from addt_dsl.runtime.trace import ActorTrack, Trace
from addt_dsl.runtime.triggers import Conditions, condition_checker

DT = 0.01
NAMES = ("ego", "lead")


def fake_run(n: int, seed: int):
    """A run's record of `n` samples (random fields, a NaN now and then) and what a
    snapshot reads of the run besides it."""
    rng = np.random.default_rng(seed)
    block = rng.normal(0.0, 10.0, (n, len(NAMES), len(FIELDS)))
    block[rng.random(block.shape) < 0.05] = np.nan
    rec = SimpleNamespace(block=block, names=list(NAMES),
                          rec={name: dict(zip(FIELDS, block.transpose(1, 2, 0)[i])) for i, name in enumerate(NAMES)})
    variables = {"v": rng.normal(0.0, 1.0, n)}
    run = SimpleNamespace(
        dt=DT, ego_plan=SimpleNamespace(length_m=4.5, width_m=1.9),
        agents=[SimpleNamespace(name="lead", length_m=4.0, width_m=1.8)],
        ego_road=SimpleNamespace(road_id="r"), agent_roads={"lead": SimpleNamespace(road_id="r")},
        stack=SimpleNamespace(latency={"perception": 0.0}, objects_seen=0), lights=None,
        red_margins={}, sign_margins={}, edges={}, ends={}, variable_records=variables, wrong_ways={}, offs={},
        lane_ids=False, named_steps=())
    run.conditions = Conditions(run)
    return run, rec


def full_trace(run, rec) -> Trace:
    n = rec.block.shape[0]
    sizes = {"ego": (4.5, 1.9), "lead": (4.0, 1.8)}  # (as `fake_run` declares them)
    actors = {name: ActorTrack(name, *sizes[name], **{f: rec.rec[name][f] for f in FIELDS}, frame="r")
              for name in NAMES}
    return Trace(DT, np.arange(n) * DT, actors, {"perception": np.zeros(n)}, object_count=np.zeros(n),
                 variables=run.variable_records)


signals = st.sampled_from(["s(ego)", "s(lead)", "speed(lead)", "x(ego)", "gap(ego,lead)", "var(v)"])
atoms = st.builds(lambda sig, op, value: Binary(op=op, left=Signal(name=sig), right=Num(value=value)),
                  signals, st.sampled_from([">", ">=", "<", "<=", "==", "!="]),
                  st.floats(-20.0, 20.0, allow_nan=False))
conditions = st.recursive(atoms, lambda inner: st.builds(lambda op, a, b: Binary(op=op, left=a, right=b),
                                                          st.sampled_from(["and", "or", "implies"]), inner, inner),
                          max_leaves=4)


@settings(max_examples=60, deadline=None)
@given(conditions, st.integers(0, 2**16))
def test_a_condition_at_each_sample_is_the_whole_traces_verdict_there(condition, seed):
    run, rec = fake_run(40, seed)
    trace = full_trace(run, rec)
    expected = oracles.verdicts(condition, compute_signals(trace, oracles.prepare(condition).signals), DT)
    # Samples out of order and again: a snapshot taken anew keeps nothing of the last one.
    for k in (*range(40), 7, 3, 39, 0):
        assert condition_checker(run, rec, k)(condition) == bool(expected[k]), k


def test_live_settings_and_conditions_read_their_own_snapshots():
    run, rec = fake_run(10, 1)
    value = Signal(name="speed(lead)")
    live = run.conditions.live_value(value, rec, 4)
    assert live == rec.block[4, 1, FIELDS.index("speed")] or np.isnan(live)
    # A condition's snapshot at another sample leaves the live one (still sample 4) as it was.
    condition_checker(run, rec, 8)(Binary(op=">", left=value, right=Num(value=0.0)))
    assert run.conditions.snapshot(rec, 8).actors["lead"].speed[0] == rec.block[8, 1, FIELDS.index("speed")]
    again = run.conditions.live_value(value, rec, 4)
    assert again == live or (np.isnan(again) and np.isnan(live))


def test_a_formula_is_prepared_once_per_expression():
    run, _ = fake_run(5, 2)
    condition = Binary(op=">", left=Signal(name="s(ego)"), right=Num(value=1.0))
    first = run.conditions.formula(condition)
    assert run.conditions.formula(condition) is first
    assert first.signals == ("s(ego)",)
    twin = Binary(op=">", left=Signal(name="s(ego)"), right=Num(value=1.0))  # equal, another object
    assert run.conditions.formula(twin) == first


def batch_of(recs):
    """The records as a batch's (`phases.Record.batch`): their blocks views of one block
    (`BatchRows`), in reversed order within it, each with its index and actor columns."""
    from addt_dsl.runtime.phases import BatchRows

    n = max(rec.block.shape[0] for rec in recs)
    first = np.array([0, *np.cumsum([len(rec.names) for rec in reversed(recs)])], dtype=np.int64)
    block = np.full((n, first[-1], len(FIELDS)), 7.0)
    rows = BatchRows(block, first, np.zeros((first[-1], 2)))
    for i, rec in enumerate(reversed(recs)):
        view = block[:rec.block.shape[0], first[i]:first[i + 1]]
        view[...] = rec.block
        rec.block, rec.batch_rows, rec.index = view, rows, i
        rec.actor_index = {name: j for j, name in enumerate(rec.names)}
        rec.rec = {name: dict(zip(FIELDS, view.transpose(1, 2, 0)[j])) for j, name in enumerate(rec.names)}


@settings(max_examples=40, deadline=None)
@given(conditions, st.lists(st.integers(0, 2**16), min_size=2, max_size=6, unique=True), st.integers(0, 39),
       st.booleans())
def test_runs_asking_a_condition_alike_get_their_own_verdicts_from_one_evaluation(condition, seeds, k, batched):
    """`prefetch` answers each run what its own snapshot says (the whole trace's verdict at
    k), for a condition object of each run's own (equal formulas), and the checker takes it
    from there without evaluating again; `batched`: the records a batch's (field signals
    read from its block at once)."""
    from addt_dsl.runtime import triggers

    runs = []
    for seed in seeds:
        run, rec = fake_run(40, seed)
        own = condition.model_copy(deep=True)  # (each run binds its own)
        run.scripts = {"lead": SimpleNamespace(asks=lambda t, own=own: iter([own]))}
        runs.append((run, rec, own))
    if batched:
        batch_of([rec for _, rec, _ in runs])
    triggers.prefetch([r for r, _, _ in runs], [rec for _, rec, _ in runs], k)
    for run, rec, own in runs:
        trace = full_trace(run, rec)
        expected = oracles.verdicts(condition, compute_signals(trace, oracles.prepare(condition).signals), DT)
        assert run.conditions.answered(own, k) == bool(expected[k])
        assert run.conditions.answered(own, k + 1) is None and run.conditions.answered(condition, k) is None
    # The checker answers from the prefetched verdict (the evaluator is not asked again).
    real, triggers.oracles.satisfied = triggers.oracles.satisfied, None
    try:
        for run, rec, own in runs:
            assert condition_checker(run, rec, k)(own) == run.conditions.answered(own, k)
    finally:
        triggers.oracles.satisfied = real


def test_a_condition_on_named_steps_or_over_time_is_left_to_each_run():
    from addt_dsl.expr import Temporal
    from addt_dsl.runtime.triggers import _alike

    atom = Binary(op=">", left=Signal(name="s(lead)"), right=Num(value=1.0))
    assert _alike(oracles.prepare(atom))
    assert not _alike(oracles.prepare(Temporal(op="eventually", lo_s=0.0, hi_s=1.0, arg=atom)))
    started = Binary(op=">", left=Signal(name="started(lead.go)"), right=Num(value=0.0))
    assert not _alike(oracles.prepare(Binary(op="and", left=atom, right=started)))
    assert not _alike(oracles.prepare(Binary(op=">", left=Num(value=2.0), right=Num(value=1.0))))
    assert not _alike(oracles.prepare(Binary(op=">", left=Signal(name="nosuch(lead)"), right=Num(value=1.0))))
