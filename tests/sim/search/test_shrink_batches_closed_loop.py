"""Shrinking closed-loop runs in batches: examples/ten_faults.addt shrinks to the same
counterexample, with the same stats and the same trace digests, one candidate at a time,
8 at a time, and 4 at a time on two workers; `addtc shrink --batch 8` writes the same files
as `--batch 1`. (The meaning at any batch: tests/unit/search/test_shrink_batches.py.)"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from addt_dsl.compiler import compile_file
from addt_dsl.search.cache import RunCache
from addt_dsl.search.shrink import Shrinker
from addt_dsl.sweep import expand

ROOT = Path(__file__).resolve().parents[3]
EXAMPLE = ROOT / "examples" / "ten_faults.addt"

pytestmark = pytest.mark.slow


def _shrink(plan, spec, batch, jobs):
    cache = RunCache()
    try:
        shrinker = Shrinker(spec, nominal_plan=plan, cache=cache, max_simulations=150, batch=batch, jobs=jobs)
        r = shrinker.run()
        digests = {k: (cache.results[k].digest, cache.results[k].status) for k in shrinker.judged}
    finally:
        cache.close()
    stats = [(s.name, s.candidates, s.simulations, s.accepted, s.rejected) for s in r.stats]
    summary = (shrinker.kept, r.best.key(), r.outcome.digest, r.target.id, stats, r.simulations, r.cache_hits,
               r.rounds, r.budget_exhausted, r.changes)
    return summary, digests, r


def test_the_shrink_is_the_same_at_batch_1_and_n_on_one_job_and_two_workers():
    plan = compile_file(EXAMPLE).plan
    (spec,) = expand(plan).specs
    one, digests, r1 = _shrink(plan, spec, 1, 1)
    assert [f.kind for f in r1.best.faults] == ["stuck"] and r1.ran_ahead == 0
    for batch, jobs in ((8, 1), (4, 2)):
        summary, more, r = _shrink(plan, spec, batch, jobs)
        assert summary == one, (batch, jobs)
        assert {k: more[k] for k in digests} == digests  # every judged run: the same trace
        assert r.ran_ahead > 0 and r.simulations + r.ran_ahead <= 150


def _cli(ten_faults_shrunk, batch: int) -> tuple[str, dict]:
    out, proc = ten_faults_shrunk(batch)  # `addtc shrink examples/ten_faults.addt --batch N ...`
    assert proc.returncode == 1, proc.stderr
    (addt,) = out.glob("*.addt")
    report = json.loads(proc.stdout)
    return addt.read_text(), report


def test_addtc_shrink_batch_writes_the_same_counterexample(ten_faults_shrunk):
    text1, report1 = _cli(ten_faults_shrunk, 1)
    text8, report8 = _cli(ten_faults_shrunk, 8)
    assert text8 == text1

    assert (report1["batch"], report1["ran_ahead"], report8["batch"]) == (1, 0, 8) and report8["ran_ahead"] > 0
    assert Path(report8["counterexample"]).name == Path(report1["counterexample"]).name

    def strip(report):  # wall times, the directory and the runs ahead differ; everything else is the same
        drop = {"seconds", "counterexample", "batch", "ran_ahead"}
        return json.loads(json.dumps(report), object_hook=lambda d: {k: v for k, v in d.items() if k not in drop})
    assert strip(report8) == strip(report1)
