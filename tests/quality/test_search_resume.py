"""`addtc falsify` and `addtc shrink` killed and run again with the same seed resume from
their run cache (the one results store, OUT/runs.sqlite) and end with the same report and
the same counterexample files as an uninterrupted search."""

from __future__ import annotations

import json
import signal
import sqlite3
import time

import pytest

from tests.quality.crashkit import start, sweep_file
from tests.conftest import EXAMPLES
from tests.sim.runner_simkit import addtc

from addt_dsl.errors import EXIT_FAILED

pytestmark = pytest.mark.slow


def _cache_rows(out) -> int:
    path = out / "runs.sqlite"
    if not path.exists():
        return 0
    try:
        db = sqlite3.connect(f"{path.resolve().as_uri()}?mode=ro", uri=True, timeout=5)
        try:
            return db.execute("SELECT COUNT(*) FROM runs").fetchone()[0]
        finally:
            db.close()
    except sqlite3.Error:
        return 0


def _kill_after(args, out, cache_rows: list[int]) -> int:
    """Start `addtc args`, SIGKILL it once its cache holds each count of `cache_rows` in
    turn (a fresh process each time); how many times it was killed."""
    kills = 0
    for n in cache_rows:
        proc = start(*args)
        deadline = time.monotonic() + 120
        while _cache_rows(out) < n and proc.poll() is None:
            assert time.monotonic() < deadline
            time.sleep(0.02)
        if proc.poll() is not None:
            break
        proc.send_signal(signal.SIGKILL)
        proc.communicate()
        kills += 1
    return kills


def _timeless(value):
    """`value` without its wall-clock `seconds` entries, at any depth."""
    if isinstance(value, dict):
        return {k: _timeless(v) for k, v in value.items() if k != "seconds"}
    if isinstance(value, list):
        return [_timeless(v) for v in value]
    return value


def _files(out) -> dict[str, object]:
    """The output directory's counterexamples and reports, with what differs between two
    directories or two processes taken out (the directory's name, wall-clock seconds)."""
    found = {}
    for p in sorted(out.iterdir()):
        if p.suffix == ".addt":
            found[p.name] = p.read_text()
        elif p.name.endswith(".report.json"):
            found[p.name] = _timeless(json.loads(p.read_text().replace(str(out), "OUT")))
    return found


def _report(stdout: str, out) -> dict:
    return _timeless(json.loads(stdout.replace(str(out), "OUT")))


def test_falsify_killed_and_run_again_ends_with_the_same_report(tmp_path):
    scenario = sweep_file(tmp_path, duration="3 s")
    base = ("falsify", scenario, "--budget-runs", "32", "--batch", "4", "--seed", "7",
            "--shrink-simulations", "10", "--format", "json")
    clean_out = tmp_path / "clean"
    clean = addtc(*base, "--out", clean_out)
    assert clean.returncode == EXIT_FAILED, clean.stderr

    out = tmp_path / "killed"
    args = (*base, "--out", out)
    assert _kill_after(args, out, [6, 20]) == 2, "the search ended before it could be killed twice"
    resumed = addtc(*args)
    assert resumed.returncode == EXIT_FAILED, resumed.stderr
    assert _report(resumed.stdout, out) == _report(clean.stdout, clean_out)
    assert _files(out) == _files(clean_out) and _files(out)


@pytest.mark.parametrize("batch", ["1", "8"])  # at 8 a kill can fall inside a batch of candidates
def test_shrink_killed_and_run_again_ends_with_the_same_counterexample(tmp_path, batch, ten_faults_shrunk):
    scenario = EXAMPLES / "ten_faults.addt"  # ten faults shrink to one in about 50 simulations (+20 ahead at 8)
    base = ("shrink", scenario, "--no-animation", "--format", "json", "--batch", batch)
    clean_out, clean = ten_faults_shrunk(int(batch))  # the same command, uninterrupted (the session's)
    assert clean.returncode == EXIT_FAILED, clean.stderr

    out = tmp_path / "killed"
    args = (*base, "--out", out)
    assert _kill_after(args, out, [8, 25]) == 2, "the shrink ended before it could be killed twice"
    resumed = addtc(*args)
    assert resumed.returncode == EXIT_FAILED, resumed.stderr
    assert _report(resumed.stdout, out) == _report(clean.stdout, clean_out)
    assert _files(out) == _files(clean_out) and _files(out)
