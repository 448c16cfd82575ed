"""Faults of the tool itself: the retry policy, lost runs kept out of the store
and run again on resume, plan identity by content, the `--timeout` values, atomic writes."""

import pytest
from tests.unit.runtime.runner_testkit import (KILLED, KILLED_ONCE, OK, RAISE, SEGFAULT, fake_record, fake_run,
                                              plan_of, scenario)

from addt_dsl import cli
from addt_dsl.compiler import compile_file
from addt_dsl.errors import EXIT_INCOMPLETE, time_bound
from addt_dsl.atomic import atomic_path, write_text
from addt_dsl.reporting.summary import store_dataframe, store_summary
from addt_dsl.runtime.executor import BOUND_REAL_TIME_FACTOR, BOUND_STARTUP_S, Attempts, LocalExecutor, \
    run_sweep, run_time_bound_s
from addt_dsl.runtime.result import RunResult, Verdict
from addt_dsl.runtime.store import ResultStore, StoreMismatch, plan_hash
from addt_dsl.sweep import SweepStream, expand

PLAN = plan_of(scenario([OK]))
SPEC = expand(PLAN).specs[0]


def _unfinished(status, error):
    return RunResult.unfinished(SPEC, status, error, 0.1, seq=0)


def test_external_deaths_are_retried_up_to_n_then_lost():
    attempts = Attempts(2)
    died = lambda: _unfinished("crashed", "worker process killed by signal 9 during the run")  # noqa: E731
    assert attempts.judge(0, died(), external=True) == "retry"
    assert attempts.judge(0, died(), external=True) == "retry"
    last = died()
    assert attempts.judge(0, last, external=True) == "lost"
    assert last.status == "lost" and "on each of 3 attempt(s); not stored" in last.error
    assert attempts.retried == 2
    assert Attempts(0).judge(0, died(), external=True) == "lost"


def test_a_crash_the_same_way_twice_is_stored_and_a_different_one_retried():
    attempts = Attempts(3)
    assert attempts.judge(0, _unfinished("crashed", "ValueError: x\ntraceback 1")) == "retry"
    assert attempts.judge(0, _unfinished("crashed", "KeyError: y\ntraceback")) == "retry"  # not the same way
    assert attempts.judge(0, _unfinished("crashed", "KeyError: y\nanother traceback")) == "done"
    assert attempts.judge(1, _unfinished("timeout", "run exceeded the 5 s timeout")) == "retry"
    assert attempts.judge(1, _unfinished("timeout", "run exceeded the 5 s timeout")) == "done"
    assert attempts.judge(2, _unfinished("memory", "resident memory 4100 MB over")) == "retry"
    assert attempts.judge(2, _unfinished("memory", "resident memory 4300 MB over")) == "done"
    assert Attempts(0).judge(3, _unfinished("crashed", "ValueError: x")) == "done"
    record = fake_record(SPEC)
    assert attempts.judge(4, record) == "done"  # a verdict is never retried


def test_lost_runs_are_not_stored_and_run_again_on_resume(tmp_path):
    text = scenario([OK, KILLED, KILLED_ONCE, SEGFAULT, RAISE])
    plan = plan_of(text.replace("runner test <script>alert(1)</script>", f"markers {tmp_path}"))
    executor = LocalExecutor(2, run_fn=fake_run, retries=1)
    with ResultStore(tmp_path / "r.sqlite", plan) as store:
        outcome = run_sweep(SweepStream(plan), store, executor)
        stored = {int(r.cell["mode"]): r for r in store.records()}
    assert [int(r.cell["mode"]) for r in outcome.lost] == [KILLED]
    assert "killed by signal 9" in outcome.lost[0].error
    assert set(stored) == {OK, KILLED_ONCE, SEGFAULT, RAISE}
    assert stored[KILLED_ONCE].status == "ok"  # killed once from outside, then run again
    assert stored[SEGFAULT].status == "crashed" and "signal 11" in stored[SEGFAULT].error
    assert stored[RAISE].status == "crashed" and "RuntimeError: boom" in stored[RAISE].error
    assert executor.retried == 4  # once each: KILLED (retries=1), KILLED_ONCE, SEGFAULT and RAISE
    # The lost run is not a verdict: a resume runs it (and only it) again.
    with ResultStore(tmp_path / "r.sqlite", plan) as store:
        again = run_sweep(SweepStream(plan), store, LocalExecutor(1, run_fn=fake_run, retries=0))
    assert (again.skipped, len(again.lost)) == (4, 1)


def test_run_time_bound():
    assert run_time_bound_s(SPEC) == BOUND_STARTUP_S + SPEC.plan.duration_s / BOUND_REAL_TIME_FACTOR
    assert run_time_bound_s(SPEC, 7.5) == 7.5
    assert run_time_bound_s(SPEC, None) is None and run_time_bound_s(SPEC, 0) is None
    assert time_bound("auto") == "auto" and time_bound("12") == 12.0 and time_bound("0") is None
    for bad in ("-1", "nan", "soon"):
        with pytest.raises(Exception, match="auto, 0"):
            time_bound(bad)


def test_the_plan_is_identified_by_content_not_by_its_path(tmp_path, monkeypatch):
    (tmp_path / "sub").mkdir()
    path = tmp_path / "sub" / "s.addt"
    path.write_text(scenario([OK, 6]))
    a = compile_file(path).plan
    monkeypatch.chdir(tmp_path / "sub")
    b = compile_file("./s.addt").plan
    assert a.source_file != b.source_file
    assert plan_hash(a) == plan_hash(b)
    assert [s.key() for s in expand(a).specs] == [s.key() for s in expand(b).specs]
    with ResultStore(tmp_path / "r.sqlite", a) as store:
        store.add(fake_record(expand(a).specs[0]))
    with ResultStore(tmp_path / "r.sqlite", b) as store:  # the same plan: resumes
        assert len(store) == 1
    path.write_text(scenario([OK, 7]))
    c = compile_file(path).plan
    with pytest.raises(StoreMismatch, match=r"scenario changed; to keep those results run into a new store beside "
                                            rf"it, --store {tmp_path}/r-{plan_hash(c)[:8]}\.sqlite, or use --fresh"):
        ResultStore(tmp_path / "r.sqlite", c)


def test_errors_are_counted_apart_from_failures(tmp_path):
    plan = plan_of(scenario([OK, 6, 7]))
    with ResultStore(tmp_path / "r.sqlite", plan) as store:
        for i, spec in enumerate(expand(plan).specs):
            r = fake_record(spec, seq=i)
            if i == 1:
                r.verdicts = [Verdict("moving", "hard", -1.0, False, 0.1)]
            if i == 2:
                r = RunResult.unfinished(spec, "crashed", "RuntimeError: boom", 0.1, seq=i)
            store.add(r)
        totals = store_summary(store)
        df = store_dataframe(store)
    assert (totals["passed"], totals["failed"], totals["errors"]) == (1, 1, 1)
    assert list(df["verdict"]) == ["pass", "fail", "error"]


def test_cli_exit_3_names_the_lost_runs(tmp_path, monkeypatch, capsys):
    path = tmp_path / "s.addt"
    path.write_text(scenario([OK, KILLED]))
    monkeypatch.setattr(cli, "_executor", lambda args: LocalExecutor(1, run_fn=fake_run, retries=args.retries))
    code = cli.main([str(path), "--store", str(tmp_path / "r.sqlite"), "--retries", "1"])
    err = capsys.readouterr().err
    assert code == EXIT_INCOMPLETE
    assert "error: 1 run(s) could not be completed (c001-r000: worker process killed by signal 9" in err
    assert "not stored: run the same command again" in err


def test_atomic_writes_leave_the_old_file_on_failure(tmp_path):
    target = tmp_path / "report.html"
    write_text(target, "old")
    with pytest.raises(OSError):
        with atomic_path(target) as tmp:
            tmp.write_text("half of a new re")
            raise OSError(28, "No space left on device")
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["report.html"]
    write_text(target, "new")
    assert target.read_text() == "new"
