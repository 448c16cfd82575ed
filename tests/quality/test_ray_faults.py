"""The fault tests on the Ray executor, kept light (2 CPUs): a Ray worker
killed mid-run is resubmitted, and a killed coordinator resumes; both end with the
results of an uninterrupted run."""

from __future__ import annotations

import os
import signal
import threading
import time

import pytest

from tests.quality.crashkit import (alive, assert_same_results, descendants, kill, reference, rows, start, sweep_file,
                                    wait_for_rows)
from tests.sim.runner_simkit import addtc

from addt_dsl.compiler import compile_file
from addt_dsl.errors import EXIT_FAILED
from addt_dsl.runtime.executor import run_sweep
from addt_dsl.runtime.store import ResultStore
from addt_dsl.sweep import SweepStream

pytest.importorskip("ray", reason="the Ray executor needs `ray` (the test extra installs it)")
from addt_dsl.runtime.ray_executor import RayExecutor  # noqa: E402

pytestmark = pytest.mark.slow


def _ray_tasks_running() -> list[int]:
    """Ray workers executing a run now (Ray titles a busy worker `ray::_ray_task`)."""
    found = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/cmdline", "rb") as fh:
                    if fh.read().startswith(b"ray::_ray_task"):
                        found.append(int(entry))
            except OSError:
                pass
    return found


def test_a_ray_worker_killed_mid_run_is_resubmitted(tmp_path):
    scenario = sweep_file(tmp_path, repeat=3, duration="3 s")  # 12 runs
    expected = reference(scenario, tmp_path)
    plan = compile_file(scenario).plan
    path = tmp_path / "r.sqlite"
    killed: list[int] = []

    def killer():
        wait_for_rows(path, 2, timeout_s=300)
        for _ in range(500):  # a worker busy with a run
            busy = _ray_tasks_running()
            if busy:
                killed.extend(busy[:1])
                kill(busy[:1])
                return
            threading.Event().wait(0.01)

    executor = RayExecutor(jobs=2, init_kwargs={"num_cpus": 2})
    with ResultStore(path, plan) as store:
        thread = threading.Thread(target=killer, daemon=True)
        thread.start()
        outcome = run_sweep(SweepStream(plan), store, executor)
        thread.join()
    assert killed, "no Ray worker was seen running a task"
    assert executor.retried >= 1 and not outcome.lost
    assert_same_results(rows(path), expected)


def test_a_killed_ray_coordinator_resumes(tmp_path):
    scenario = sweep_file(tmp_path, repeat=3, duration="3 s")
    expected = reference(scenario, tmp_path)
    store = tmp_path / "r.sqlite"
    args = (scenario, "--executor", "ray", "--jobs", "2", "--store", store, "--no-report")
    proc = start(*args)
    wait_for_rows(store, 3, proc, timeout_s=300)
    assert proc.poll() is None, "the sweep ended before it could be killed"
    ray_processes = list(descendants(proc.pid))  # the local Ray instance it started
    proc.send_signal(signal.SIGKILL)
    proc.communicate()
    before = rows(store)
    # A SIGKILLed driver's Ray instance winds itself down, but some agents outlive it: end
    # those this test started (the next sweep starts its own instance either way).
    deadline = time.monotonic() + 5
    while any(alive(p) for p in ray_processes) and time.monotonic() < deadline:
        time.sleep(0.2)
    kill([p for p in ray_processes if alive(p)])
    resumed = addtc(*args, timeout=600)
    assert resumed.returncode == EXIT_FAILED, resumed.stderr
    assert f"resuming: {len(before)} run(s)" in resumed.stderr
    assert set(before) <= set(rows(store))
    assert_same_results(rows(store), expected)
