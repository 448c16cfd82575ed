"""A search's runs go through the batch engine (`RunCache` steps each generation's misses
together): the same falsification, seed fixed, finds the same runs, results and failures at
batch 1 and batch N, on one job and on two workers. (The Bayesian sampler proposes `jobs`
points per step after its initial design, so its search depends on the job count by design;
uniform sampling does not.)"""

from pathlib import Path

from addt_dsl.compiler import compile_file
from addt_dsl.search.cache import RunCache
from addt_dsl.search.falsify import Falsifier

EXAMPLE = Path(__file__).resolve().parents[3] / "examples" / "search" / "stuck_accel.addt"


def _search(plan, batch, jobs, sampler="bo"):
    cache = RunCache(batch=batch)
    try:
        report = Falsifier(plan, seed=3, batch=6, jobs=jobs, sampler=sampler, cache=cache).run(
            budget_runs=12, shrink_simulations=0)
        runs = sorted((r.key, r.status, r.digest, repr(r.verdicts)) for r in cache.results.values())
    finally:
        cache.close()
    summary = report.to_json()
    del summary["seconds"]
    return summary, runs


def test_falsify_is_the_same_at_any_batch_and_job_count():
    plan = compile_file(EXAMPLE).plan.model_copy(update={"duration_s": 2.0})  # short runs, same search
    for jobs in (1, 2):
        one = _search(plan, batch=1, jobs=jobs)
        assert len(one[1]) == 12 and len({digest for _, _, digest, _ in one[1]}) == 12
        assert _search(plan, batch=None if jobs == 1 else 3, jobs=jobs) == one  # 1 job: a call's misses at once
    uniform = _search(plan, batch=1, jobs=1, sampler="random")
    assert _search(plan, batch=None, jobs=1, sampler="random") == uniform
    assert _search(plan, batch=3, jobs=2, sampler="random") == uniform
