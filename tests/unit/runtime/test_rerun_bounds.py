"""`addtc trace`/`report` execute a stored run again in a worker bounded as a sweep's (the
run's time bound, the memory limit), not in the calling process without bounds; the inline
executor gives each run the same time bound."""

from __future__ import annotations

import os
import time
import weakref

import pytest

from addt_dsl import cli
from addt_dsl.compiler import compile_source
from addt_dsl.errors import EXIT_INCOMPLETE
from addt_dsl.reporting import trace_view
from addt_dsl.runtime import executor as ex
from addt_dsl.runtime.store import ResultStore
from addt_dsl.sweep import expand

SRC = """
scenario short {
  duration 30 s
  road r {
    line length 600 m
    lanes right 2
  }
  ego car on r lane -1 at 10 m speed 10 m/s {
    stack bev cruise_speed 10 m/s
  }
}
"""


@pytest.fixture()
def stored(tmp_path):
    plan = compile_source(SRC, "short.addt").plan
    path = tmp_path / "results.sqlite"
    with ResultStore(path, plan, fresh=True) as store:
        ex.run_sweep(expand(plan).specs, store, ex.InlineExecutor())
    return tmp_path


def test_trace_reruns_in_a_worker_process(stored):
    with ResultStore(stored / "results.sqlite") as store:
        record = next(store.records())
        run = trace_view.rerun(store, record)
    assert run.reproduced and len(run.trace.time) > 0


def test_a_rerun_past_its_time_bound_is_a_one_line_error(stored, monkeypatch, capsys):
    monkeypatch.setattr(ex, "run_time_bound_s", lambda spec, timeout_s="auto": 0.001)
    with ResultStore(stored / "results.sqlite") as store:
        record = next(store.records())
        with pytest.raises(trace_view.RerunFailed, match="timeout"):
            trace_view.rerun(store, record)
    assert cli.main(["trace", str(stored), record.run_id]) == EXIT_INCOMPLETE
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: run c000-r000, executed again, did not finish (timeout") and "\n" not in err


def _sleeps(spec, seq=-1, worker=""):
    time.sleep(5)
    raise AssertionError("not stopped at its bound")


def test_the_inline_executor_bounds_each_runs_time(monkeypatch):
    spec = expand(compile_source(SRC, "short.addt").plan).specs[0]
    monkeypatch.setattr(ex, "run_time_bound_s", lambda spec, timeout_s="auto": 0.2)
    t0 = time.monotonic()
    import signal

    outer = signal.getitimer(signal.ITIMER_REAL)  # pytest-timeout's alarm, where it uses one
    (record,) = list(ex.InlineExecutor(_sleeps).imap([(0, spec)]))
    assert record.status == "timeout" and time.monotonic() - t0 < 2
    # The bound is lifted after the run: the process's alarm is as it was, less the time spent.
    after = signal.getitimer(signal.ITIMER_REAL)
    assert after == (0.0, 0.0) if outer[0] == 0 else (0 < after[0] <= outer[0] and after[1] == outer[1])
    monkeypatch.undo()  # the default bound: the real run finishes within it
    (ok,) = list(ex.InlineExecutor().imap([(0, spec)]))
    assert ok.status == "ok"


class _Held(list):
    """What a run holds (a list that a weak reference can follow)."""


_HELD: list = []  # weak references to what `_grows` held


def _grows(spec, seq=-1, worker=""):
    held = _Held()
    _HELD.append(weakref.ref(held))
    for _ in range(400):  # up to 4 GB, 10 MB every 5 ms, each page written (resident)
        held.append(b"\x01" * (10 * 2**20))
        time.sleep(0.005)
    raise AssertionError("not stopped at its memory limit")


@pytest.mark.skipif(ex.rss_mb(os.getpid()) is None, reason="needs /proc")
def test_the_inline_executor_bounds_the_memory_a_run_adds():
    spec = expand(compile_source(SRC, "short.addt").plan).specs[0]
    import signal

    signal.setitimer(signal.ITIMER_REAL, 500.0)  # an outer alarm (pytest-timeout's): kept across the run
    (record,) = list(ex.InlineExecutor(_grows, memory_limit_mb=100).imap([(0, spec)]))
    left = signal.setitimer(signal.ITIMER_REAL, 0)[0]
    assert 400.0 < left <= 500.0
    assert record.status == "memory" and "over the 100 MB limit" in record.error, record.error
    # What the run held was let go (the RSS may not shrink: the allocator may keep freed
    # pages for reuse, depending on what earlier tests in the process freed).
    assert _HELD and all(ref() is None for ref in _HELD)
    # `--executor inline` passes the command's --memory-limit and --timeout on.
    from addt_dsl.cli import _executor

    class Args:  # the parsed command line, as far as `_executor` reads it
        executor, timeout, memory_limit = "inline", 7.0, 123.0
    got = _executor(Args())
    assert (got.timeout_s, got.memory_limit_mb) == (7.0, 123.0)
    single = ex.local_executor(1, _grows, memory_limit_mb=50, timeout_s=9.0)
    assert isinstance(single, ex.InlineExecutor) and (single.timeout_s, single.memory_limit_mb) == (9.0, 50)
