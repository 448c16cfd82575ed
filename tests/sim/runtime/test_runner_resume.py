"""A sweep killed with SIGKILL and restarted with the same command resumes: nothing lost,
nothing duplicated, and the results equal an uninterrupted sweep's."""

import signal
import sqlite3
import subprocess
import time

import pytest

from tests.quality.crashkit import descendants
from tests.sim.runner_simkit import REPO, addtc, addtc_command, addtc_env, limit_scenario

from addt_dsl.compiler import compile_file
from addt_dsl.sweep import expand

pytestmark = pytest.mark.slow


def _rows(path) -> list[tuple]:
    if not path.exists():
        return []
    try:
        with sqlite3.connect(path, timeout=5) as db:
            return db.execute("SELECT run_id, key, session, digest FROM runs").fetchall()
    except sqlite3.OperationalError:  # tables not created yet
        return []


def _pids_alive(pids) -> list[int]:
    alive = []
    for pid in pids:
        try:
            with open(f"/proc/{pid}/stat") as fh:
                if fh.read().split()[2] != "Z":
                    alive.append(pid)
        except OSError:
            pass
    return alive


def test_sigkill_mid_sweep_then_resume(tmp_path):
    scenario = limit_scenario(tmp_path, repeat=6, duration="5 s")  # 24 runs
    expected = {(s.run_id, s.key()) for s in expand(compile_file(scenario).plan).specs}
    store = tmp_path / "results.sqlite"
    args = (scenario, "--jobs", "2", "--store", store, "--no-report")

    proc = subprocess.Popen(addtc_command(*args), env=addtc_env(), cwd=REPO,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while len(_rows(store)) < 4:
        assert proc.poll() is None, "the sweep ended before it could be killed"
        assert time.monotonic() < deadline
        time.sleep(0.02)
    helpers = set(descendants(proc.pid))  # the fork server and the workers forked from it
    assert len(helpers) >= 3
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    before = _rows(store)
    assert 4 <= len(before) < len(expected), "killed mid-sweep"
    # Workers do not outlive a killed coordinator (they would burn CPU on runs nobody records).
    deadline = time.monotonic() + 10
    while _pids_alive(helpers) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not _pids_alive(helpers)

    resumed = addtc(*args)
    assert resumed.returncode == 1, resumed.stderr  # cell limit=70 m fails
    assert f"resuming: {len(before)} run(s)" in resumed.stderr
    after = _rows(store)
    assert {(rid, key) for rid, key, _, _ in after} == expected  # nothing lost
    assert len(after) == len(expected)  # nothing duplicated
    assert set(before) <= set(after)  # committed runs kept as they were, from session 1
    assert {row[2] for row in before} == {1}
    assert sorted(row for row in after if row[2] == 2) == sorted(set(after) - set(before))  # the rest: run now

    reference = tmp_path / "reference.sqlite"
    clean = addtc(scenario, "--jobs", "2", "--store", reference, "--no-report")
    assert clean.returncode == 1
    assert {(r, k, d) for r, k, _, d in _rows(reference)} == {(r, k, d) for r, k, _, d in after}
