"""The search's run cache is a results store: runs of many plans, by key, reused across
invocations, misses run on the sweep executors."""

from __future__ import annotations

import math

import pytest

from tests.unit.search.search_testkit import judged, kitchen_sink_plan

from addt_dsl.plan import RunSpec
from addt_dsl.runtime.result import Failure
from addt_dsl.search.cache import RunCache


def flaky_judge(spec: RunSpec):
    """Fails `no_collision` when the gap is below 30 m, with a flipped bit to keep."""
    gap = spec.params.get("gap", 30.0)
    failures = (Failure("no_collision", "clearance(ego) > 0 m [with lead]", 2.5, gap - 30.0),) if gap < 30.0 else ()
    return judged(spec, {"no_collision": gap - 30.0}, failures, drawn_values={0: (61, 62)})


def _spec(gap: float, duration_s: float = 10.0) -> RunSpec:
    plan = kitchen_sink_plan()
    plan = plan.model_copy(update={"duration_s": duration_s})
    return RunSpec(plan=plan, params={**plan.nominal_params(), "gap": gap}, seed=7, faults=[], run_id=f"g{gap}")


def test_a_cache_file_is_reused_by_the_next_invocation(tmp_path):
    path = tmp_path / "cache.sqlite"
    specs = [_spec(20.0), _spec(40.0), _spec(20.0, duration_s=5.0)]  # two plans
    first = RunCache(path, evaluator=flaky_judge)
    results = first.get_many(specs)
    assert (first.simulations, first.hits) == (3, 0)
    first.close()

    again = RunCache(path, evaluator=flaky_judge)
    replayed = again.get_many(specs)
    assert (again.simulations, again.hits) == (0, 3)
    for a, b in zip(results, replayed):
        assert (a.key, a.passed, a.failures, a.drawn_values) == (b.key, b.passed, b.failures, b.drawn_values)
    assert replayed[0].failures[0].mode == "clearance(ego) > 0 m [with lead]"
    # Each stored run rebuilds its own RunSpec, plan included.
    for spec in specs:
        stored = again.store.find(spec.key())
        assert again.store.spec(stored).key() == spec.key()
    again.close()


def test_misses_run_on_local_workers_with_the_same_results():
    specs = [_spec(g) for g in (10.0, 25.0, 35.0, 50.0)]
    inline = RunCache(evaluator=flaky_judge).get_many(specs, jobs=1)
    workers = RunCache(evaluator=flaky_judge).get_many(specs, jobs=2)
    assert [(r.key, r.passed, r.robustness) for r in inline] == [(r.key, r.passed, r.robustness) for r in workers]
    assert [r.passed for r in workers] == [False, False, True, True]
    assert math.isclose(workers[0].failures[0].robustness, -20.0)


def test_a_file_that_is_no_store_is_refused_with_a_message(tmp_path):
    old = tmp_path / "cache.jsonl"
    old.write_text('{"key": "0123", "status": "ok"}\n')  # an earlier version's JSON-lines cache
    with pytest.raises(ValueError, match="is not a results store.*JSON lines"):
        RunCache(old, evaluator=flaky_judge)


def test_a_worker_that_keys_a_run_otherwise_still_answers_for_it(monkeypatch):
    """The code fingerprint is read from the source files when a process first needs it: a
    worker started after an edit (a long test run, a kept worker) keys the same spec
    otherwise. The cache found its miss under another key (KeyError); the coordinator, which
    dispatched the run, owns its key."""
    from addt_dsl import fingerprint

    specs = [_spec(g) for g in (10.0, 50.0)]
    identity = dict(fingerprint._identity())
    # This process reads other code than the workers, which fork from a server that did not.
    monkeypatch.setattr(fingerprint, "_identity", lambda: tuple({**identity, "source": "edited"}.items()))
    cache = RunCache(evaluator=flaky_judge)
    try:
        results = cache.get_many(specs, jobs=2)
    finally:
        cache.close()
    assert [r.key for r in results] == [s.key() for s in specs]
    assert [r.passed for r in results] == [False, True]


def sized_judge(spec: RunSpec):
    return flaky_judge(spec)


def _sized_batch(specs):
    """flaky_judge over a batch, each result noting its batch's size (drawn value 9)."""
    results = [flaky_judge(s) for s in specs]
    for r in results:
        r.drawn_values[9] = (len(specs),)
    return results


sized_judge.batched = _sized_batch


@pytest.mark.parametrize("jobs, batch, size", [(1, None, 6), (2, 3, 3), (1, 1, None)])
def test_misses_are_judged_in_batches(jobs, batch, size):
    """An evaluator with a batched form gets a call's misses as batches (all of them on one
    job; `batch` given: that many), with the results of one by one."""
    specs = [_spec(g) for g in (10.0, 25.0, 35.0, 50.0, 12.0, 44.0)]
    cache = RunCache(evaluator=sized_judge, batch=batch)
    try:
        results = cache.get_many(specs, jobs=jobs)
    finally:
        cache.close()
    assert [r.drawn_values.get(9, (None,))[0] for r in results] == [size] * 6
    alone = [flaky_judge(s) for s in specs]
    assert [(r.key, r.passed, r.robustness, r.failures) for r in results] == \
        [(r.key, r.passed, r.robustness, r.failures) for r in alone]
