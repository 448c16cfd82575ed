"""What the local executor's dispatch keeps true while it hands runs over cheaply: every run
is run with its own plan, also when plans outnumber what a worker keeps (a search's
candidates each have one) and when a crashed worker is replaced; exactly one record per
run; and the runs of a search's call, split evenly over the workers, give the same records
as on one job."""

from pathlib import Path

import pytest
from tests.unit.runtime.runner_testkit import OK, SEGFAULT, plan_echo_run, plan_of, scenario

from addt_dsl.runtime import executor as executor_module
from addt_dsl.runtime.executor import LocalExecutor, batch_size
from addt_dsl.search.cache import RunCache
from addt_dsl.sweep import SweepStream


def test_a_call_is_split_evenly_over_the_workers():
    assert batch_size(8, 2) == 4  # was 1: eight batches of one, no batch engine
    assert batch_size(7, 2) == 4 and batch_size(3, 2) == 2
    assert batch_size(5, 1) == 5 and batch_size(40, 1) == 16  # capped
    assert batch_size(100, 2) == 16 and batch_size(0, 2) == 1


@pytest.mark.timeout(120)
def test_each_run_gets_its_own_plan_past_the_kept_plans(monkeypatch):
    monkeypatch.setattr(executor_module, "PLANS_KEPT", 2)
    base = plan_of(scenario([OK, SEGFAULT]))
    plans = [base.model_copy(update={"description": f"plan {i}"}) for i in range(6)]
    ok, crash = list(SweepStream(base))
    # Plans come back after others pushed them out; a worker dies mid-sweep (its fresh
    # successor holds no plans); batches of 3 mix plans.
    order = [0, 1, 2, 0, 3, 4, 1, 5, 2, 0, 5, 3, 4, 1]
    specs = [ok.model_copy(update={"plan": plans[i], "run_id": f"r{n:02d}"}) for n, i in enumerate(order)]
    specs[6] = crash.model_copy(update={"plan": plans[1], "run_id": "r06"})
    executor = LocalExecutor(2, run_fn=plan_echo_run, timeout_s=None, memory_limit_mb=None, retries=0,
                             keep_workers=True, batch=3)
    spawned = []
    spawn = executor._spawn
    monkeypatch.setattr(executor, "_spawn", lambda ctx: spawned.append(1) or spawn(ctx))
    try:
        records = list(executor.imap(enumerate(specs)))
        # Two workers, and one each time the crashing run killed its worker (in its batch, then
        # alone): no batch failed for want of a plan (a failed batch's runs go again alone,
        # which would hide it in the records).
        assert len(spawned) == 4
        assert sorted(r.seq for r in records) == list(range(len(specs)))  # one record per run
        for r in records:
            if r.seq == 6:
                assert r.status == "crashed" and "signal 11" in r.error
            else:
                assert (r.status, r.digest) == ("ok", specs[r.seq].plan.description), r.seq
        # Bounded: the coordinator's registry and what each kept worker holds.
        assert len(executor._plans) <= 2
        assert executor._kept and all(len(w.plans) <= 3 for w in executor._kept)  # at most a batch's
    finally:
        executor.close()


@pytest.mark.timeout(180)
def test_a_search_call_gives_the_same_records_on_one_and_two_jobs():
    plan = plan_of(scenario([0, 2], repeat=3, duration="0.3 s"))  # real closed-loop runs
    specs = list(SweepStream(plan))
    results = {}
    for jobs in (1, 2):
        cache = RunCache()
        try:
            results[jobs] = [(r.run_id, r.status, r.digest, repr(r.verdicts)) for r in cache.get_many(specs, jobs)]
        finally:
            cache.close()
    assert results[1] == results[2]
    assert len({d for _, _, d, _ in results[1]}) > 1


def test_workers_stay_small_in_a_process_that_loaded_the_whole_package(tmp_path):
    # A test session (or a notebook) may have loaded every addt_dsl module, torch's too:
    # preloading all of them in the forkserver put ~300 MB in every worker, and each run of
    # the full suite's guard tests ended `memory` under their 250 MB limit.
    import subprocess
    import sys

    code = (
        "import importlib, pkgutil, sys, pytest, addt_dsl\n"
        "for m in pkgutil.walk_packages(addt_dsl.__path__, 'addt_dsl.'):\n"
        "    try:\n        importlib.import_module(m.name)\n"
        "    except Exception:\n        pass\n"
        # The tests whose runs go to workers: the inline executor's run in this process.
        "sys.exit(pytest.main(['-q', '-p', 'no:cacheprovider', '-k', 'not inline',\n"
        "                      'tests/unit/runtime/test_runner_batch.py']))\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                          cwd=Path(__file__).resolve().parents[3])
    assert done.returncode == 0, done.stdout[-2000:]
