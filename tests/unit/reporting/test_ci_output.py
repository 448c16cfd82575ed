"""Off a terminal (CI logs): periodic progress lines instead of a bar, and tables at full
width (no "no_coll..." cut at 80 columns). pytest's capture makes stdout and stderr
non-terminals, as in CI."""

import sys

import pytest
from tests.unit.runtime.runner_testkit import fake_record, scenario

from addt_dsl import cli
from addt_dsl.reporting.progress import ProgressLines
from addt_dsl.runtime import executor as executor_module

LONG = "no_collision_with_any_other_road_user_whatsoever"


def _fake_run(spec, seq=-1, worker="", on_result=None):
    """`executor.run_spec` without a simulation."""
    record = fake_record(spec, seq, worker)
    if on_result is not None:
        on_result(record)
    return record


class _Clock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


class _Run:
    passed = True
    status = "ok"
    warned_oracles = ()


def test_progress_lines_every_5_percent_or_10_seconds():
    clock, lines = _Clock(), []
    progress = ProgressLines(total=200, done=20, write=lines.append, clock=clock)
    for _ in range(9):  # 9 runs in 9 s: under 5 % (10 runs) and under 10 s
        clock.t += 1.0
        progress(_Run())
    assert lines == []
    clock.t += 1.0
    progress(_Run())  # the 10th run: 5 %
    assert lines == ["progress: 30/200 runs (15 %), 0 failed, 10s elapsed, about 2m50s left"]
    clock.t += 11.0
    progress(_Run())  # one run, but 11 s since the last line
    assert len(lines) == 2 and lines[-1].startswith("progress: 31/200 runs")
    for _ in range(169):
        progress(_Run())
    assert lines[-1] == "progress: 200/200 runs (100 %), 0 failed, 21s elapsed"  # always a last line


def test_sweep_prints_progress_lines_and_full_width_table_off_a_terminal(monkeypatch, tmp_path, capsys):
    assert not sys.stdout.isatty() and not sys.stderr.isatty()
    monkeypatch.delenv("COLUMNS", raising=False)
    monkeypatch.setattr(executor_module, "run_spec", _fake_run)
    path = tmp_path / "s.addt"
    path.write_text(scenario([0, 1, 2, 3, 4, 5], repeat=4).replace("moving:", f"{LONG}:"))
    assert cli.main([str(path), "--executor", "inline"]) == 0
    captured = capsys.readouterr()
    progress = [line for line in captured.err.splitlines() if line.startswith("progress: ")]
    assert len(progress) >= 5 and progress[-1].startswith("progress: 24/24 runs (100 %)")
    header = next(line for line in captured.out.splitlines() if "verdict" in line)
    assert LONG in header and "…" not in captured.out
    assert max(len(line) for line in captured.out.splitlines()) > 80


@pytest.mark.parametrize("columns", ["60"])
def test_columns_still_wins(monkeypatch, tmp_path, capsys, columns):
    monkeypatch.setenv("COLUMNS", columns)
    monkeypatch.setattr(executor_module, "run_spec", _fake_run)
    path = tmp_path / "s.addt"
    path.write_text(scenario([0]).replace("moving:", f"{LONG}:"))
    assert cli.main([str(path), "--executor", "inline"]) == 0
    assert max(len(line) for line in capsys.readouterr().out.splitlines()) <= int(columns)
