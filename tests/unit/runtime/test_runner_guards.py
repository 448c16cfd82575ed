"""LocalExecutor guards: timeout, memory (in flight and peak), crashes, recycling."""

from collections import Counter

import pytest

from tests.unit.runtime.runner_testkit import HANG, HOG, OK, RAISE, SEGFAULT, SPIKE, fake_run, plan_of, scenario

from addt_dsl.runtime.executor import LocalExecutor, run_local, run_sweep
from addt_dsl.runtime.store import ResultStore
from addt_dsl.sweep import SweepStream


def test_each_failure_is_recorded_and_the_sweep_goes_on(tmp_path):
    plan = plan_of(scenario([OK, HANG, SEGFAULT, HOG, RAISE, SPIKE], repeat=2))
    store = ResultStore(tmp_path / "r.sqlite", plan)
    # retries: test_runner_faults. The timeout leaves the hog time to touch its 400 MB and
    # the coordinator to see it on a loaded machine (at 2.5 s, under pytest-xdist beside
    # other work, the hog ran out of time before it was seen).
    executor = LocalExecutor(2, timeout_s=5.0, memory_limit_mb=250, run_fn=fake_run, retries=0)
    outcome = run_sweep(SweepStream(plan), store, executor)

    records = list(store.records())
    assert len(records) == outcome.ran == 12
    by_mode = {}
    for r in records:
        by_mode.setdefault(int(r.cell["mode"]), set()).add(r.status)
    assert by_mode == {OK: {"ok"}, HANG: {"timeout"}, SEGFAULT: {"crashed"}, HOG: {"memory"},
                       RAISE: {"crashed"}, SPIKE: {"memory"}}
    errors = {int(r.cell["mode"]): r.error for r in records}
    assert "signal 11" in errors[SEGFAULT]
    assert "RuntimeError: boom" in errors[RAISE]
    assert errors[HOG].startswith("resident memory")  # caught while the run was in flight
    # Freed before the run ends: caught by a poll if one fell inside the spike, else by the peak.
    assert "resident memory" in errors[SPIKE]
    assert "5 s timeout" in errors[HANG]
    assert outcome.passed == 2 and outcome.failed == 10
    assert Counter(f for r in records for f in r.failed_oracles) == Counter(
        {"timeout": 2, "crashed": 4, "memory": 4})


def test_workers_are_recycled_after_max_tasks(tmp_path):
    plan = plan_of(scenario([OK], repeat=5))
    records = run_local(SweepStream(plan), jobs=1, max_tasks_per_child=2, run_fn=fake_run)
    assert [r.status for r in records] == ["ok"] * 5
    workers = [r.worker for r in sorted(records, key=lambda r: r.seq)]
    assert len(set(workers)) == 3
    assert workers[0] == workers[1] != workers[2] == workers[3] != workers[4]


def test_no_guard_configured_still_runs_everything(tmp_path):
    plan = plan_of(scenario([OK, RAISE], repeat=2))
    records = run_local(SweepStream(plan), jobs=2, timeout_s=None, memory_limit_mb=None, run_fn=fake_run)
    assert sorted(r.status for r in records) == ["crashed", "crashed", "ok", "ok"]
    assert [r.run_id for r in records] == sorted(r.run_id for r in records)


def test_kept_workers_serve_later_calls_until_closed():
    plan = plan_of(scenario([OK], repeat=4))
    specs = list(SweepStream(plan))
    executor = LocalExecutor(2, run_fn=fake_run, keep_workers=True)
    first = {r.worker for r in executor.imap(enumerate(specs[:2]))}
    kept = [w.process for w in executor._kept]
    assert len(kept) == 2 and all(p.is_alive() for p in kept)
    second = {r.worker for r in executor.imap(enumerate(specs[2:]))}
    assert second <= first  # the same processes ran the second call
    executor.close()
    assert not executor._kept and not any(p.is_alive() for p in kept)
    # Without keep_workers nothing outlives a call.
    plain = LocalExecutor(2, run_fn=fake_run)
    list(plain.imap(enumerate(specs[:2])))
    assert plain._kept == []


@pytest.mark.timeout(120)
def test_workers_start_only_for_runs_that_need_them(monkeypatch):
    """`--jobs 100000` on a sweep of 2 runs starts 2 processes (it started 100000: a 2-run
    sweep with `--jobs 200` took ~40 s on a loaded 2-core machine, one with 100000 did not
    end), and a session records the workers it could use (100000000000000000000 overflowed
    SQLite's INTEGER: 'internal error: OverflowError')."""
    plan = plan_of(scenario([OK], repeat=2))
    executor = LocalExecutor(50, run_fn=fake_run)
    spawned = []
    spawn = executor._spawn
    monkeypatch.setattr(executor, "_spawn", lambda ctx: spawned.append(1) or spawn(ctx))
    assert [r.status for r in executor.imap(enumerate(SweepStream(plan)))] == ["ok", "ok"]
    assert len(spawned) == 2
