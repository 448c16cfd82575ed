"""Shared pieces of the fault-tolerance tests: a short closed-loop sweep, its
stored rows, the rows of an uninterrupted run to compare with, and process helpers.

Every test breaks something (the coordinator, a worker, the store, the disk, a second
sweep) and then checks the store against an uninterrupted run of the same sweep: the
same (run id, key) pairs, none twice, the same statuses, verdicts and trace digests.
"""

from __future__ import annotations

import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

from tests.sim.runner_simkit import REPO, addtc_command, addtc_env, limit_scenario

from addt_dsl.compiler import compile_file
from addt_dsl.runtime.executor import BATCH_MAX, InlineExecutor, run_sweep
from addt_dsl.runtime.store import ResultStore
from addt_dsl.sweep import SweepStream, expand

ROW = "run_id, key, status, passed, failed_oracles, digest"


def sweep_file(tmp_path: Path, repeat: int = 2, duration: str = "1.5 s") -> Path:
    """The station-limit sweep (2 limits x 2 drop rates x `repeat`); cell limit=70 m fails."""
    return limit_scenario(tmp_path, repeat=repeat, duration=duration)


def rows(path: Path) -> list[tuple]:
    """The stored runs, sorted, read without touching the store (no lock, read-only)."""
    if not Path(path).exists():
        return []
    uri = Path(path).resolve().as_uri()
    for mode in ("ro", "ro&immutable=1"):  # immutable: a WAL store in a read-only directory
        try:
            db = sqlite3.connect(f"{uri}?mode={mode}", uri=True, timeout=5)
            try:
                return sorted(db.execute(f"SELECT {ROW} FROM runs").fetchall())
            finally:
                db.close()
        except sqlite3.Error:  # not created yet, or mid-creation
            continue
    return []


def reference(scenario: Path, tmp_path: Path) -> list[tuple]:
    """The rows of an uninterrupted run of the sweep (in this process, in batches as a
    worker steps them: a RunSpec determines its run, so the executor does not matter)."""
    plan = compile_file(scenario).plan
    path = tmp_path / "reference.sqlite"
    with ResultStore(path, plan, fresh=True) as store:
        run_sweep(SweepStream(plan), store, InlineExecutor(batch=BATCH_MAX))
    out = rows(path)
    assert len(out) == len(expand(plan).specs)
    return out


def assert_same_results(got: list[tuple], expected: list[tuple]) -> None:
    """0 lost, 0 duplicated, identical verdicts and digests."""
    ids = [r[0] for r in got]
    assert len(ids) == len(set(ids)), "a run is stored twice"
    assert {r[0] for r in expected} - set(ids) == set(), "runs lost"
    assert got == expected


def start(*args, **kwargs) -> subprocess.Popen:
    return subprocess.Popen(addtc_command(*args), env=addtc_env(), cwd=REPO, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, **kwargs)


def wait_for_rows(path: Path, n: int, proc: subprocess.Popen | None = None, timeout_s: float = 120) -> int:
    deadline = time.monotonic() + timeout_s
    while True:
        count = len(rows(path))
        if count >= n:
            return count
        if proc is not None and proc.poll() is not None:
            return count
        assert time.monotonic() < deadline, f"no {n} stored runs after {timeout_s} s"
        time.sleep(0.02)


def descendants(pid: int) -> dict[int, int]:
    """pid -> depth below `pid` (1: children, 2: grandchildren, ...), from /proc."""
    parents = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as fh:
                    parents[int(entry)] = int(fh.read().rsplit(")", 1)[1].split()[1])
            except (OSError, ValueError, IndexError):
                pass
    found, frontier, depth = {}, {pid}, 0
    while frontier:
        depth += 1
        frontier = {p for p, parent in parents.items() if parent in frontier} - set(found)
        found.update({p: depth for p in frontier})
    return found


def alive(pid: int) -> bool:
    """Whether a thread of `pid` still runs. A killed multi-threaded process (a worker that
    has loaded numba's kernels, or torch) shows its main thread as a zombie while its other
    threads, which hold its open files (the worker's pipe), are still exiting."""
    try:
        tasks = os.listdir(f"/proc/{pid}/task")
    except OSError:
        return False
    for task in tasks:
        try:
            with open(f"/proc/{pid}/task/{task}/stat") as fh:
                if fh.read().rsplit(")", 1)[1].split()[0] not in ("Z", "X"):
                    return True
        except OSError:
            pass
    return False


def local_workers(pid: int | None = None) -> list[int]:
    """The LocalExecutor workers of process `pid` (default this one): forked by its fork
    server, so two levels below it."""
    return sorted(p for p, depth in descendants(pid or os.getpid()).items() if depth == 2 and alive(p))


def kill(pids, sig=signal.SIGKILL) -> None:
    for pid in pids:
        try:
            os.kill(pid, sig)
        except ProcessLookupError:
            pass


def wait_dead(pids, timeout_s: float = 10) -> None:
    deadline = time.monotonic() + timeout_s
    while any(alive(p) for p in pids):
        assert time.monotonic() < deadline
        time.sleep(0.02)


def python() -> str:
    return sys.executable
