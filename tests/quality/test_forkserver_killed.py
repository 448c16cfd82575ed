"""The multiprocessing forkserver (the process every local worker forks from) killed in the
middle of a sweep: the executor starts a new one, replaces the workers it took down with it
and runs their runs again (infrastructure, never stored as a crash); the store ends as an
uninterrupted sweep's. Before, a worker started while the server died raised `EOFError` out
of the sweep (`internal error: EOFError`, exit 3)."""

from __future__ import annotations

import os
import signal
import threading
from multiprocessing import forkserver

import pytest

from tests.quality.crashkit import assert_same_results, reference, rows, sweep_file

from addt_dsl.compiler import compile_file
from addt_dsl.runtime.executor import LocalExecutor, run_sweep
from addt_dsl.runtime.store import ResultStore
from addt_dsl.sweep import SweepStream

pytestmark = pytest.mark.slow


def _server_pid() -> int:
    pid = forkserver._forkserver._forkserver_pid
    assert pid is not None, "no forkserver running"
    return pid


@pytest.mark.parametrize("mid_start", [False, True], ids=["while-workers-run", "while-a-worker-starts"])
def test_a_killed_forkserver_is_restarted_and_the_lost_runs_rerun(mid_start, tmp_path, monkeypatch):
    scenario = sweep_file(tmp_path, repeat=2)  # 8 runs of 1.5 s
    expected = reference(scenario, tmp_path)
    plan = compile_file(scenario).plan
    killed: list[int] = []

    armed: list[int] = []
    connect = forkserver.connect_to_new_process

    def connect_then_kill(fds):
        # The next worker's request goes to a stopped server, which never answers; killed
        # 0.3 s later, it leaves the coordinator reading EOF where the worker's pid should be.
        if armed:
            pid = armed.pop()
            os.kill(pid, signal.SIGSTOP)
            threading.Timer(0.3, os.kill, (pid, signal.SIGKILL)).start()
        return connect(fds)

    monkeypatch.setattr(forkserver, "connect_to_new_process", connect_then_kill)

    def specs():
        for i, spec in enumerate(SweepStream(plan)):
            if i == 3 and not killed:  # two workers busy, two runs done
                pid = _server_pid()
                killed.append(pid)
                if mid_start:
                    armed.append(pid)
                else:
                    os.kill(pid, signal.SIGKILL)
            yield spec

    path = tmp_path / "r.sqlite"
    # One run per worker: every run after the kill needs a worker forked by a new server.
    executor = LocalExecutor(2, max_tasks_per_child=1)
    with ResultStore(path, plan) as store:
        outcome = run_sweep(specs(), store, executor)
    assert killed and not outcome.lost
    assert _server_pid() != killed[0]  # a new server
    assert_same_results(rows(path), expected)
