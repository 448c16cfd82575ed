"""Shrinking in batches (`Shrinker(batch=N)`) against the synthetic judge of
test_shrink_engine: the same shrink as one candidate at a time, whatever the batch.

Where a candidate must be simulated, the shrink runs it with the candidates its pass
would propose next were each rejected, and the pass takes the first failing one in its
own order. The checks below compare everything a shrink reports (the kept candidates in
order, the result, per-pass stats, `simulations`, `cache_hits`, rounds) at batch 1 and
batch N; the judge makes several candidates of one batch fail (checked: the batches are
not vacuous), so taking any but the pass's first failing one gives another shrink.
"""

from __future__ import annotations

from collections import Counter

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from tests.unit.search.search_testkit import concrete_faults, kitchen_sink_plan
from tests.unit.search.test_shrink_engine import CULPRIT, Judge, _culprit, _spec

from addt_dsl.search.cache import RunCache
from addt_dsl.search.shrink import Shrinker


def judge_run(spec):
    """A module-level judge: local workers can be handed it."""
    return Judge()(spec)


class BatchJudge(Judge):
    """The synthetic judge, recording the batches it is handed and how many of each fail."""

    def __init__(self):
        super().__init__()
        self.batches: list[tuple[int, int]] = []  # (size, failing)
        self.batched = self._batch

    def _batch(self, specs):
        results = [self(s) for s in specs]
        self.batches.append((len(specs), sum(not r.passed for r in results)))
        return results


def _summary(result, shrinker):
    stats = [(s.name, s.candidates, s.simulations, s.accepted, s.rejected) for s in result.stats]
    return (shrinker.kept, result.best.key(), result.outcome.key, result.target.id, stats, result.simulations,
            result.cache_hits, result.rounds, result.budget_exhausted, result.changes)


def _shrink(spec, batch, budget=400, jobs=1, cache=None, judge=None):
    judge = judge if judge is not None else BatchJudge()
    cache = cache or RunCache(evaluator=judge if jobs == 1 else judge_run)
    shrinker = Shrinker(spec, nominal_plan=kitchen_sink_plan(), cache=cache, max_simulations=budget,
                        batch=batch, jobs=jobs)
    result = shrinker.run()
    assert result.simulations + result.ran_ahead <= budget
    assert result.batch == batch
    return _summary(result, shrinker), result, judge


def _noise_spec(n=8, gap=20.0):
    noise = [CULPRIT.model_copy(update={"kind": "drop", "target": "lidar", "settings": {"rate": 0.1 * i},
                                        "seed": i, "start_s": 0.1 * i}) for i in range(n)]
    return _spec(noise[:3] + [CULPRIT] + noise[3:], gap=gap)


@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(concrete_faults(kitchen_sink_plan(), max_faults=8), st.integers(0, 8), st.floats(10.0, 39.0),
       st.sampled_from([4, 8]))
def test_a_batched_shrink_is_the_shrink_one_at_a_time(noise, position, gap, batch):
    noise = [f for f in noise if not _culprit(f, kitchen_sink_plan().duration_s)]
    spec = _spec(noise[:position] + [CULPRIT] + noise[position:], gap)
    one, _, _ = _shrink(spec, 1)
    many, result, judge = _shrink(spec, batch)
    assert many == one
    assert max(judge.calls.values()) == 1, "a candidate was simulated twice"
    assert len(judge.calls) == 1 + result.simulations + result.ran_ahead - 1  # every run counted, the original too
    assert all(size <= batch for size, _ in judge.batches)


def test_batches_hold_several_failing_candidates_and_the_pass_order_decides():
    one, r1, j1 = _shrink(_noise_spec(), 1)
    many, r8, j8 = _shrink(_noise_spec(), 8)
    assert many == one
    assert not j1.batches and r1.ran_ahead == 0  # one at a time: never a batch
    # Not vacuous: batches of several runs where more than one fails (a shrink taking another
    # failing candidate than the pass's first would keep another sequence).
    assert max(size for size, _ in j8.batches) == 8
    assert sum(failing >= 2 for _, failing in j8.batches) >= 3
    assert r8.ran_ahead > 0 and len(j8.batches) < r1.simulations / 2


def test_the_budget_counts_runs_ahead_and_a_spent_budget_stops_where_one_at_a_time_would():
    full, _, _ = _shrink(_noise_spec(), 1)
    for budget in range(4, 70, 5):
        many, result, judge = _shrink(_noise_spec(), 8, budget=budget)
        assert sum(judge.calls.values()) <= budget + 1  # the original run, then the budget
        if not result.budget_exhausted:
            assert many == _shrink(_noise_spec(), 1, budget=budget)[0] == full
        else:  # the sequential shrink given the candidates this one judged stops at the same one
            assert many == _shrink(_noise_spec(), 1, budget=result.simulations)[0]
            assert many[0] == full[0][:len(many[0])]  # the kept candidates: a prefix of the full shrink's


def test_two_workers_shrink_the_same_as_one_job():
    one, _, _ = _shrink(_noise_spec(5), 1)
    assert _shrink(_noise_spec(5), 4, jobs=2)[0] == one


def test_runs_in_the_cache_are_not_run_again_and_the_shrink_is_the_same():
    judge = BatchJudge()
    cache = RunCache(evaluator=judge)
    first, r1, _ = _shrink(_noise_spec(), 8, cache=cache, judge=judge)
    calls = Counter(judge.calls)
    again, r2, _ = _shrink(_noise_spec(), 8, cache=cache, judge=judge)
    assert judge.calls == calls, "a cached run was run again"
    assert again == first and r2.ran_ahead == r1.ran_ahead  # the count does not depend on what the cache held
    assert _shrink(_noise_spec(), 1, cache=cache, judge=judge)[0] == first
