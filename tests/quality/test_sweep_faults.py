"""Sweeps that survive faults: the coordinator killed at random points, workers
killed busy and idle, a hung external stack, two sweeps on one store. Each ends with
exactly the results of an uninterrupted run: 0 lost, 0 duplicated, identical verdicts and
digests."""

from __future__ import annotations

import random
import signal
import socket
import threading
import time

import pytest

from tests.quality.crashkit import (assert_same_results, kill, local_workers, reference, rows, start,
                                    sweep_file, wait_dead, wait_for_rows)
from tests.sim.runner_simkit import addtc

from addt_dsl.compiler import compile_file, compile_source
from addt_dsl.errors import EXIT_FAILED, EXIT_INCOMPLETE
from addt_dsl.runtime.executor import LocalExecutor, run_sweep
from addt_dsl.runtime.store import ResultStore
from addt_dsl.sweep import SweepStream

pytestmark = pytest.mark.slow


def test_coordinator_killed_at_random_points_then_resumed(tmp_path):
    # 60 runs: enough that a fast machine cannot finish the sweep between two kills (20
    # runs did, on CI, inside one kill's random delay).
    scenario = sweep_file(tmp_path, repeat=15, duration="3 s")
    expected = reference(scenario, tmp_path)
    out = tmp_path / "out"
    store = out / "results.sqlite"
    args = (scenario, "--jobs", "2", "--out", out, "--animations", "0")
    rng = random.Random(24)
    kills = 0
    for attempt in range(5):
        proc = start(*args)
        # Anywhere: during start-up (compiling, opening the store), or a random number of
        # runs further on, and a random instant after that run's commit.
        if attempt == 0:
            time.sleep(rng.uniform(0.2, 1.5))
        else:
            wait_for_rows(store, len(rows(store)) + rng.randint(1, 4), proc)
            time.sleep(rng.uniform(0.0, 0.1))
        if proc.poll() is not None:
            break
        before = rows(store)
        proc.send_signal(signal.SIGKILL)
        proc.communicate()
        kills += 1
        after_kill = rows(store)
        assert set(before) <= set(after_kill)  # committed runs stay as they were
    assert kills >= 2, "the sweep finished before it could be killed twice"
    final = addtc(*args)
    assert final.returncode == EXIT_FAILED, final.stderr  # the limit=70 m cell fails its oracle
    assert "Traceback" not in final.stderr
    assert_same_results(rows(store), expected)
    assert (out / "report.html").read_text().rstrip().endswith("</html>")


def _kill_workers_when(store_path, n_rows: int, killed: list) -> threading.Thread:
    def killer():
        wait_for_rows(store_path, n_rows, timeout_s=120)
        pids = local_workers()
        killed.extend(pids)
        kill(pids)

    thread = threading.Thread(target=killer, daemon=True)
    thread.start()
    return thread


def test_busy_workers_killed_from_outside_are_replaced_and_their_runs_retried(tmp_path):
    scenario = sweep_file(tmp_path, repeat=3, duration="3 s")  # 12 runs
    expected = reference(scenario, tmp_path)
    plan = compile_file(scenario).plan
    path = tmp_path / "r.sqlite"
    killed: list[int] = []
    executor = LocalExecutor(2)
    with ResultStore(path, plan) as store:
        thread = _kill_workers_when(path, 2, killed)
        outcome = run_sweep(SweepStream(plan), store, executor)
        thread.join()
    assert len(killed) == 2  # both workers, killed mid-run (as the OOM killer would)
    assert executor.retried >= 1 and not outcome.lost
    assert_same_results(rows(path), expected)


def test_a_worker_that_dies_idle_is_replaced(tmp_path):
    scenario = sweep_file(tmp_path, repeat=1)
    expected = reference(scenario, tmp_path)
    plan = compile_file(scenario).plan
    killed: list[int] = []

    def specs():
        for i, spec in enumerate(SweepStream(plan)):
            if i in (1, 3):  # the one worker has just finished a run and waits for the next
                pids = local_workers()
                assert len(pids) == 1
                kill(pids)
                wait_dead(pids)
                killed.extend(pids)
            yield spec

    path = tmp_path / "r.sqlite"
    executor = LocalExecutor(1)
    with ResultStore(path, plan) as store:
        outcome = run_sweep(specs(), store, executor)  # before: BrokenPipeError out of _dispatch
    assert len(killed) == 2
    assert executor.retried == 0 and not outcome.lost  # no run was lost: it went to the new worker
    assert_same_results(rows(path), expected)


class _HungStack:
    """A stack server that accepts and then never answers (`dribble`: one byte every
    0.2 s, so that no single socket read ever waits long)."""

    def __init__(self, dribble: bool):
        self.sock = socket.create_server(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self.dribble = dribble
        self.conns = []
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self):
        while True:
            try:
                conn, _ = self.sock.accept()
            except OSError:
                return
            self.conns.append(conn)
            if self.dribble:
                threading.Thread(target=self._drip, args=(conn,), daemon=True).start()

    @staticmethod
    def _drip(conn):
        try:
            conn.sendall(b"\x00\x00")  # the start of a length prefix, then a byte at a time
            while True:
                time.sleep(0.2)
                conn.sendall(b"\x01")
        except OSError:
            return

    def close(self):
        self.sock.close()
        for c in self.conns:
            c.close()


HUNG = """
scenario hung {
  duration 2 s
  road r {
    line length 200 m
    lanes right 1 width 3.5 m
  }
  param speed = 10 m/s in [5 m/s, 20 m/s]
  ego car on r lane -1 at 10 m speed speed {
    stack external address "127.0.0.1:PORT" timeout 1 s
  }
  expect {
    moving: always ego.speed > 1 m/s
  }
  sweep {
    grid speed in [8, 12] m/s
  }
}
"""


@pytest.mark.parametrize("dribble", [False, True], ids=["silent", "byte-at-a-time"])
def test_a_hung_external_stack_ends_each_run_within_its_deadline(tmp_path, dribble):
    server = _HungStack(dribble)
    try:
        path = tmp_path / "hung.addt"
        path.write_text(HUNG.replace("PORT", str(server.port)))
        t0 = time.monotonic()
        result = addtc(path, "--jobs", "2", "--store", tmp_path / "r.sqlite", timeout=120)
        elapsed = time.monotonic() - t0
    finally:
        server.close()
    assert result.returncode == EXIT_FAILED, result.stderr  # the stack failed: a verdict, not a hang
    stored = rows(tmp_path / "r.sqlite")
    assert [r[2] for r in stored] == ["detected", "detected"]
    assert all("stack_health" in r[4] for r in stored)
    assert elapsed < 60  # 1 s per exchange, not for ever (start-up included)
    # Run again: the same verdicts (the stored runs are taken, nothing runs twice).
    again = addtc(path, "--jobs", "2", "--store", tmp_path / "r.sqlite", timeout=120)
    assert again.returncode == EXIT_FAILED and rows(tmp_path / "r.sqlite") == stored


@pytest.mark.parametrize("fresh", [False, True], ids=["resume", "fresh"])
def test_two_sweeps_on_one_store_never_mix(tmp_path, fresh):
    # 120 runs of 12 s: the first sweep must still be running when the second has started up
    # (with 24 short runs, and later with 120 of 3 s once the engine stepped runs in batches, a
    # fast first sweep finished before the second took the lock).
    scenario = sweep_file(tmp_path, repeat=30, duration="12 s")
    expected = reference(scenario, tmp_path)
    store = tmp_path / "out" / "results.sqlite"
    first = start(scenario, "--jobs", "1", "--store", store, "--no-report")
    wait_for_rows(store, 1, first)
    assert first.poll() is None, "the first sweep ended before the second started"
    second = addtc(scenario, "--jobs", "1", "--store", store, "--no-report", *(["--fresh"] if fresh else []))
    assert second.returncode == EXIT_INCOMPLETE
    err = second.stderr.strip()
    assert err.count("\n") == 0 and "Traceback" not in err, err
    assert f"in use by another sweep (pid {first.pid}:" in err
    _, first_err = first.communicate(timeout=300)
    assert first.returncode == EXIT_FAILED, first_err
    assert_same_results(rows(store), expected)
    with ResultStore(store, readonly=True) as s:
        assert {r.session for r in s.records()} == {1}  # one writer, one session


def test_the_default_time_bound_follows_the_scenario(tmp_path, monkeypatch):
    from addt_dsl.runtime import executor as executor_module
    from tests.unit.runtime.runner_testkit import HANG, OK, fake_run, scenario

    plan = compile_source(scenario([OK, HANG], duration="0.5 s")).plan
    # 1 s start-up + 0.5 s simulated at 0.25x real time: a 3 s bound (computed by the coordinator).
    monkeypatch.setattr(executor_module, "BOUND_STARTUP_S", 1.0)
    monkeypatch.setattr(executor_module, "BOUND_REAL_TIME_FACTOR", 0.25)
    assert executor_module.run_time_bound_s(next(iter(SweepStream(plan)))) == 3.0
    with ResultStore(tmp_path / "r.sqlite", plan) as store:
        outcome = run_sweep(SweepStream(plan), store, LocalExecutor(2, run_fn=fake_run))
        statuses = {int(r.cell["mode"]): (r.status, r.error) for r in store.records()}
    assert statuses[OK][0] == "ok"
    assert statuses[HANG] == ("timeout", "run exceeded the 3 s timeout")
    assert outcome.statuses["timeout"] == 1  # timed out twice: retried once, then recorded
