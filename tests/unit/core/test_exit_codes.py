"""The exit-code contract (addt_dsl/errors.py) of every `addtc` command: 0 all passed,
1 a run failed an oracle, 2 usage or scenario error (one line, no traceback), 3 the tool
could not complete. Runs are faked (no simulation) through the inline executor."""

import sqlite3

import pytest
from tests.unit.runtime.runner_testkit import fake_record, plan_of, scenario

from addt_dsl import cli
from addt_dsl.errors import EXIT_FAILED, EXIT_INCOMPLETE, EXIT_OK, EXIT_USAGE, verdict_exit_code
from addt_dsl.runtime import executor as executor_module
from addt_dsl.runtime.result import RunResult, Verdict
from addt_dsl.runtime.store import ResultStore
from addt_dsl.sweep import expand
from tests.conftest import EXAMPLES

EXAMPLE = str(EXAMPLES / "overtake.addt")
FAIL, CRASH = 6, 7  # `mode` values the fake run turns into a failed and a crashed run


def _fake_run(spec, seq=-1, worker="", on_result=None):
    mode = int(spec.params["mode"])
    if mode == CRASH:
        return RunResult.unfinished(spec, "crashed", "worker died (SIGKILL)", 0.01, seq=seq, worker=worker)
    record = fake_record(spec, seq, worker)
    if mode == FAIL:
        record.verdicts = [Verdict("moving", "hard", -1.0, False, 0.1)]
    if on_result is not None:
        on_result(record)
    return record


@pytest.fixture
def fake_runs(monkeypatch):
    monkeypatch.setattr(executor_module, "run_spec", _fake_run)


def _scenario(tmp_path, modes):
    path = tmp_path / "s.addt"
    path.write_text(scenario(modes))
    return str(path)


@pytest.mark.parametrize(("modes", "code"), [([0], EXIT_OK), ([0, FAIL], EXIT_FAILED),
                                             ([0, FAIL, CRASH], EXIT_INCOMPLETE), ([CRASH], EXIT_INCOMPLETE)])
def test_run_and_report_exit_codes(fake_runs, tmp_path, capsys, modes, code):
    path = _scenario(tmp_path, modes)
    out = tmp_path / "out"
    assert cli.main([path, "--executor", "inline", "--out", str(out), "--no-report"]) == code
    # `addtc report` over the same store gives the same code.
    assert cli.main(["report", str(out), "--animations", "0"]) == code
    assert "Traceback" not in capsys.readouterr().err


def test_crashed_runs_are_never_exit_1():
    assert verdict_exit_code({"ok": 3, "crashed": 1}, failed=2) == EXIT_INCOMPLETE
    assert verdict_exit_code({"ok": 3, "timeout": 1}, failed=1) == EXIT_INCOMPLETE
    assert verdict_exit_code({"ok": 2, "detected": 1}, failed=1) == EXIT_FAILED  # stack_health: a verdict
    assert verdict_exit_code({"ok": 3}, failed=0) == EXIT_OK


BAD_USAGES = [
    [EXAMPLE, "--limit", "-1"], [EXAMPLE, "--jobs", "0"], [EXAMPLE, "--timeout", "-1"],
    [EXAMPLE, "--timeout", "nan"], [EXAMPLE, "--animations", "-2"], [EXAMPLE, "--memory-limit", "-5"],
    [EXAMPLE, "--max-tasks-per-child", "0"], [EXAMPLE, "--jobs", "two"], [EXAMPLE, "--address", "x"],
    [EXAMPLE, "--bogus"], ["nonexistent.addt"], ["report", "/nonexistent/dir"], ["report", "--animations", "-1", "."],
    ["schema", "--write", "/nonexistent/dir/schema.json"], ["check"], ["plan"],
    ["shrink"], ["shrink", "--store", "/nonexistent/dir"], ["shrink", EXAMPLE, "--max-simulations", "-1"],
    ["shrink", EXAMPLE, "--run-id", "no-such-run"],
    ["falsify", EXAMPLE, "--budget-runs", "-1"], ["falsify", EXAMPLE, "--batch", "0"],
    ["falsify", EXAMPLE, "--budget-seconds", "-3"], ["falsify", "nonexistent.addt"],
    ["study", "table", "nonexistent.csv", "--by", "x"], ["study", "perception", EXAMPLE, "--bands", "a,b"],
    ["study", "perception", EXAMPLE, "--bands", "20,10"], ["study", "classify", EXAMPLE, "--limit", "-1"],
    ["study", "classify", EXAMPLE, "--by", "nonexistent"], ["study", "nonsense"],
]


def _code(argv) -> int:
    """`addtc argv`'s exit code (argparse itself exits with 2 on a malformed option)."""
    try:
        return cli.main(argv)
    except SystemExit as exc:
        return exc.code


@pytest.mark.parametrize("argv", BAD_USAGES, ids=lambda a: " ".join(a).replace(str(EXAMPLES), "EX"))
def test_usage_errors_are_one_line_and_exit_2(argv, capsys):
    code = _code(argv)
    err = capsys.readouterr().err
    assert code == EXIT_USAGE, err
    assert "Traceback" not in err
    assert err.strip().splitlines()[-1].startswith(("error", "addtc")) or "error(s)" in err, err


def test_study_table_by_unknown_parameter(tmp_path, capsys):
    runs = tmp_path / "runs.csv"
    runs.write_text("run_id,passed,param.drop\nc000,True,0.1\n")
    assert cli.main(["study", "table", str(runs), "--by", "nonexistent"]) == EXIT_USAGE
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "nonexistent" in err and "drop" in err


def test_suite_by_unknown_parameter(fake_runs, tmp_path, capsys):
    suite = tmp_path / "suite"
    suite.mkdir()
    (suite / "a.addt").write_text(scenario([0]))
    assert cli.main([str(suite), "--executor", "inline", "--by", "nonexistent"]) == EXIT_USAGE
    assert "--by nonexistent" in capsys.readouterr().err


def test_damaged_store_is_exit_3_in_one_line(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "results.sqlite").write_bytes(b"this is not a database" * 100)
    assert cli.main(["report", str(out)]) == EXIT_INCOMPLETE
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert "results.sqlite is not a results store (not an SQLite file); it is left as it is" in err


def test_internal_error_is_exit_3_never_1(monkeypatch, capsys):
    def broken(args):
        raise KeyError("oops")

    monkeypatch.setattr(cli, "cmd_check", broken)
    assert cli.main(["check", EXAMPLE]) == EXIT_INCOMPLETE
    err = capsys.readouterr().err
    assert "internal error: KeyError" in err and "Traceback" not in err
    monkeypatch.setenv("ADDT_DEBUG", "1")
    assert cli.main(["check", EXAMPLE]) == EXIT_INCOMPLETE
    assert "Traceback" in capsys.readouterr().err


def test_report_of_a_store_with_failures_is_exit_1(tmp_path):
    plan = plan_of(scenario([0, 6]))
    store = ResultStore(tmp_path / "r.sqlite", plan)
    for i, spec in enumerate(expand(plan).specs):
        r = fake_record(spec, seq=i)
        if i:
            r.verdicts = [Verdict("moving", "hard", -1.0, False, 0.1)]
        store.add(r)
    store.close()
    assert cli.main(["report", str(tmp_path / "r.sqlite"), "--animations", "0"]) == EXIT_FAILED
    assert sqlite3.connect(tmp_path / "r.sqlite").execute("SELECT COUNT(*) FROM runs").fetchone() == (2,)


@pytest.mark.timeout(120)  # before workers started on demand, this started 10**20 processes
def test_more_jobs_than_runs_or_than_sqlite_holds(fake_runs, tmp_path, capsys):
    path = _scenario(tmp_path, [0])
    for jobs in ("100000", "99999999999999999999"):
        assert cli.main([path, "--jobs", jobs, "--out", str(tmp_path / jobs), "--no-report"]) == EXIT_OK
    assert "Traceback" not in capsys.readouterr().err


def test_an_output_path_that_is_a_directory_is_named(tmp_path, capsys):
    """`--junit DIR`, `--export DIR`: one line naming the path the user gave (it named the
    temporary file beside it: 'Is a directory: .../.out.qrqsau2x.tmp')."""
    plan = plan_of(scenario([0]))
    with ResultStore(tmp_path / "r.sqlite", plan) as store:
        store.add(fake_record(expand(plan).specs[0], seq=0))
    target = tmp_path / "out"
    target.mkdir()
    for option in ("--junit", "--export"):
        assert cli.main(["report", str(tmp_path / "r.sqlite"), "--out", str(tmp_path / "rep"), option,
                         str(target)]) == EXIT_USAGE
        err = capsys.readouterr().err
        assert err == f"error: Is a directory: {target}\n", err
