"""Run many RunSpecs and commit each result to the store as it finishes.

`run_sweep` is the coordinator: it walks a (lazy) stream of RunSpecs, skips the ones the
store already holds (resume), hands the rest to an executor and commits every record the
moment it arrives. It keeps nothing per run beyond the store, so its memory does not grow
with the sweep.

Executors yield `RunResult`s in completion order; a record is fully determined by its
RunSpec, so the store's contents do not depend on the executor, the worker count or the
order. Three executors:

- `LocalExecutor` (default): long-lived worker processes, each fed a batch of runs at a
  time over its own pipe (one message: the runs and the plans the worker lacks). The
  coordinator watches every busy worker: a run past its timeout is killed and recorded as
  `timeout`; a worker whose resident memory passes the limit is killed and its run
  recorded as `memory`; a worker that dies (segfault, OOM killer) has its run recorded as
  `crashed`. The worker is replaced and the sweep goes on. Workers are
  also recycled after `max_tasks_per_child` runs, like `multiprocessing.Pool`'s
  `maxtasksperchild`, to bound slow leaks.
- `InlineExecutor`: in this process, one batch after another (`batch=1`: one run after
  another), with the same time and memory bounds checked by a timer; for debugging and
  single-job searches.
- `addt_dsl.runtime.ray_executor.RayExecutor`: the same on a Ray cluster.
"""

from __future__ import annotations

import contextlib
import itertools
import multiprocessing as mp
import os
import resource
import signal
import sys
import time
import traceback
from collections import Counter, deque
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from multiprocessing.connection import wait

from addt_dsl.errors import ToolError
from addt_dsl.plan import RunSpec
from addt_dsl.runtime.execute import execute, execute_batch
from addt_dsl.runtime.result import RunResult
from addt_dsl.runtime.store import ResultStore, trace_stats

DEFAULT_MEMORY_LIMIT_MB = 4096
DEFAULT_MAX_TASKS_PER_CHILD = 500
DEFAULT_RETRIES = 2
# Plans a worker (and the coordinator, to hand them on) keeps between runs. A sweep has one
# plan; each candidate of a search has its own (~50 kB in memory), so an unbounded registry
# grew with every candidate in the coordinator and in each kept worker.
PLANS_KEPT = 64
# Modules the forkserver imports once for every worker beside the executor's: what a run
# imports at its first use (the default stack: ~35 ms a worker otherwise).
WORKER_PRELOAD = ("addt_dsl.runtime.executor", "addt_dsl.stack.bev")
_GUARD_POLL_S = 0.2  # how often busy workers are checked against timeout and memory limit

# The default time bound of a run (`timeout_s="auto"`): its simulated duration over a
# conservative real-time factor, plus start-up (forking a worker, building the world, the
# first lidar casts). The closed-loop twin runs at 1-4x real time on one core with the
# default sensors; 0.1x leaves room for a loaded machine, a large lidar or a camera, and
# still ends a hung external stack or a run stuck in a loop.
AUTO = "auto"
BOUND_REAL_TIME_FACTOR = 0.1  # simulated seconds per wall second, at the slowest expected
BOUND_STARTUP_S = 60.0

# Signals that kill a worker from outside (the OOM killer and `kill` send SIGKILL, a
# scheduler SIGTERM): infrastructure, not the run. A run that loses its worker to one is
# run again; one that loses it on every attempt is `lost`, never stored as a verdict.
EXTERNAL_SIGNALS = frozenset({signal.SIGKILL, signal.SIGTERM, signal.SIGHUP, signal.SIGINT})


# Runs a worker steps together by default (`default_batch`): at most BATCH_MAX (each run
# holds its own world, and a pybullet client where it renders or casts rays at meshes, so a
# worker's memory grows with its batch:
# docs/twin.md gives the measured bound; a killed sweep loses at most a batch per worker),
# and small enough that each worker gets BATCHES_PER_WORKER batches (the last batches of
# a sweep do not leave the other workers idle).
BATCH_MAX = 16
BATCHES_PER_WORKER = 4


def default_batch(n_runs: int, workers: int) -> int:
    """The batch size for a sweep of `n_runs` runs on `workers` workers."""
    return max(1, min(BATCH_MAX, n_runs // (max(1, workers) * BATCHES_PER_WORKER)))


def batch_size(n_runs: int, workers: int) -> int:
    """The batch size for `n_runs` runs handed at once and awaited together (a search's
    generation, a shrink's candidates): an even share per worker, up to BATCH_MAX. Unlike a
    sweep's stream there is no tail to balance beyond the call (the call ends when its last
    run does), and runs of one call are alike (candidates of one scenario); batches of one
    (`default_batch` of 8 runs on 2 workers) gave up the batch engine's gain for nothing."""
    return max(1, min(BATCH_MAX, -(-n_runs // max(1, workers))))


def run_time_bound_s(spec: RunSpec, timeout_s: float | str | None = AUTO) -> float | None:
    """The wall-clock bound of one run [s]: `timeout_s` when it is a number > 0, the default
    derived from the scenario for "auto", None (no bound) for None or 0."""
    if timeout_s == AUTO:
        from addt_dsl.cost import run_wall_seconds

        # A run the cost model expects to be slow (a large camera) gets the same tenfold margin
        # over its estimate: the compiler accepted it (docs/limits.md), the bound must not kill it.
        slowest = max(spec.plan.duration_s / BOUND_REAL_TIME_FACTOR, 10.0 * run_wall_seconds(spec.plan))
        return BOUND_STARTUP_S + slowest
    return float(timeout_s) if timeout_s else None


class Attempts:
    """The retry policy every executor applies to a run that did not finish.

    A worker killed from outside (`external`: a signal in EXTERNAL_SIGNALS, a lost Ray
    worker or node) is infrastructure: the run goes again, up to `retries` times, and one
    still not done is `lost` (not stored: a resume runs it again). Anything else that did
    not finish (an exception in the stack or the twin, a segfault, a timeout, the memory
    limit) is run once more; failing the same way twice it is stored as it is (the record
    carries the traceback), so a deterministic crash costs one retry, never a loop."""

    def __init__(self, retries: int = DEFAULT_RETRIES):
        self.retries = max(0, int(retries))
        self._seen: dict[int, list[str]] = {}
        self.retried = 0

    @staticmethod
    def signature(record: RunResult) -> str:
        if record.status in ("timeout", "memory"):
            return record.status
        return f"{record.status}: {(record.error.splitlines() or [''])[0]}"

    def judge(self, seq: int, record: RunResult, external: bool = False) -> str:
        """"done" (yield the record), "retry" (run it again) or "lost"."""
        if record.status in ("ok", "detected"):
            self._seen.pop(seq, None)
            return "done"
        seen = self._seen.setdefault(seq, [])
        sig = "external" if external else self.signature(record)
        repeated = not external and sig in seen
        seen.append(sig)
        if repeated or len(seen) > self.retries:
            del self._seen[seq]
            if external:
                record.status = "lost"
                record.error = (f"{record.error} (on each of {len(seen)} attempt(s); not stored: "
                                "run the same command again to retry it)")
            return "lost" if external else "done"
        self.retried += 1
        return "retry"


# ---------------------------------------------------------------------------- one run

def run_spec(spec: RunSpec, seq: int = -1, worker: str = "",
             on_result: Callable | None = None) -> RunResult:
    """Execute one RunSpec and summarise it (trace dropped, latency statistics kept); an
    exception becomes a `crashed` record. `on_result(result)` sees the result with its
    trace first (and may annotate it)."""
    t0 = time.perf_counter()
    try:
        record = execute(spec, keep_trace=True)
        record.stats = trace_stats(record.trace)
        if on_result is not None:
            on_result(record)
        record.seq, record.worker, record.trace = seq, worker, None
    except Exception as exc:  # noqa: BLE001 - a crashing run is recorded, the sweep goes on
        record = RunResult.unfinished(
            spec, "crashed", f"{type(exc).__name__}: {exc}\n{traceback.format_exc(limit=4)}",
            time.perf_counter() - t0, seq=seq, worker=worker)
    return record


def run_batch(specs: list[RunSpec], seqs: list[int], worker: str = "",
              on_result: Callable | None = None) -> list[RunResult]:
    """`run_spec` over a batch stepped together (`execute_batch`): the same records as one by
    one (a run's trace does not depend on its batch). A batch whose set-up fails (one run's
    world or stack cannot be built) runs its runs one by one, so only that run is `crashed`;
    so is a run whose `on_result` raises, as alone."""
    if len(specs) == 1:
        return [run_spec(specs[0], seqs[0], worker, on_result)]
    try:
        records = execute_batch(specs, keep_trace=True)
    except Exception:  # noqa: BLE001 - isolate the run that failed: each alone
        return [run_spec(spec, seq, worker, on_result) for spec, seq in zip(specs, seqs)]
    out = []
    for spec, record, seq in zip(specs, records, seqs):
        try:
            record.stats = trace_stats(record.trace)
            if on_result is not None:
                on_result(record)
        except Exception as exc:  # noqa: BLE001 - as `run_spec`: a crashing run is recorded
            record = RunResult.unfinished(spec, "crashed", f"{type(exc).__name__}: {exc}\n"
                                          f"{traceback.format_exc(limit=4)}", record.wall_time_s)
        record.seq, record.worker, record.trace = seq, worker, None
        out.append(record)
    return out


def answer(batch: list[tuple[int, RunSpec]], records: list[RunResult], worker: str = "") -> list[RunResult]:
    """Exactly one record per dispatched run, in the batch's order, each under the run's seq
    and key as the coordinator computes them. A worker keys a spec with the code fingerprint
    it read from the source files when it first needed it: one started after an edit (a long
    run, a kept worker) keys the same spec otherwise, and its record would be filed under a
    key nobody asked for. A run the worker returned no record for (a custom run function
    that dropped one) is `crashed`, never left out."""
    seqs = [seq for seq, _ in batch]
    by_seq = {r.seq: r for r in records}
    if len(records) == len(batch) and sorted(by_seq) != sorted(seqs):
        by_seq = dict(zip(seqs, records))  # all there, numbered otherwise: by position
    out = []
    for seq, spec in batch:
        record = by_seq.get(seq)
        if record is None:
            record = RunResult.unfinished(spec, "crashed", f"the worker returned {len(records)} record(s) for a "
                                          f"batch of {len(batch)} runs, none for this one", 0.0, worker=worker)
        record.seq, record.key = seq, spec.key()
        out.append(record)
    return out


def _run_fn_batch(run_fn: Callable | None) -> Callable:
    """What runs a batch for `run_fn`: `run_batch` for the default, the function's own
    `run_batch(specs, seqs, worker)` where it has one (`search.cache.Judge`), else it one
    run at a time."""
    if run_fn is None:
        return run_batch
    batched = getattr(run_fn, "run_batch", None)
    if batched is not None:
        return batched
    return lambda specs, seqs, worker="": [run_fn(spec, seq, worker=worker) for spec, seq in zip(specs, seqs)]


def peak_rss_mb() -> float:
    """Peak resident set size of this process [MB]."""
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / 1024.0 if sys.platform != "darwin" else peak / 2**20


def rss_mb(pid: int) -> float | None:
    """Current resident set size of a process [MB] (Linux /proc), None if unknown."""
    try:
        with open(f"/proc/{pid}/statm") as fh:
            return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
    except (OSError, ValueError, IndexError):
        return None


def spec_fields(spec: RunSpec) -> dict:
    return {name: getattr(spec, name) for name in RunSpec.model_fields if name != "plan"}


# ---------------------------------------------------------------------------- executors

class _OverTime(BaseException):
    """Raised into an inline run at its time bound (a BaseException: `run_spec` records
    exceptions as crashes; this one is the bound, recorded as `timeout`)."""


class _OverMemory(BaseException):
    """Raised into an inline run whose memory passed the limit (recorded as `memory`)."""

    def __init__(self, grown_mb: float):
        super().__init__(grown_mb)
        self.grown_mb = grown_mb


class InlineExecutor:
    """Runs in the calling process, one after another (debugging; a search or study on one
    job). Each run has a sweep worker's bounds, checked every `_GUARD_POLL_S` by a SIGALRM
    timer (on Unix, in the main thread): its time bound (`timeout_s`, "auto" by default) and
    `memory_limit_mb` of resident memory that the run may add to this process (a worker's
    limit counts the whole worker; here what the process held before the run, its store
    and search state, is not the run's). A run past either is stopped where it is and
    recorded as `timeout` or `memory`; what it allocated is freed as it unwinds. A single
    call into C that allocates past the limit cannot be stopped midway (a worker is killed)."""

    name = "inline"
    workers = 1

    def __init__(self, run_fn: Callable | None = None, timeout_s: float | str | None = AUTO,
                 memory_limit_mb: float | None = DEFAULT_MEMORY_LIMIT_MB, batch: int = 1):
        self.run_fn = run_fn  # as LocalExecutor's
        self.timeout_s = timeout_s
        self.memory_limit_mb = memory_limit_mb if memory_limit_mb and memory_limit_mb > 0 else None
        self.batch = max(1, int(batch))  # as LocalExecutor's

    def imap(self, items: Iterable[tuple[int, RunSpec]]) -> Iterator[RunResult]:
        items = iter(items)
        while batch := list(itertools.islice(items, self.batch)):
            records = self._bounded(batch)
            if records is None:  # a batch past its bound: each run again alone, under its own
                for run in batch:
                    yield from self._bounded([run])
            else:
                yield from records

    def _bounded(self, batch: list[tuple[int, RunSpec]]) -> list[RunResult] | None:
        """A record per run of `batch`, stepped together; None when a batch of several went
        past its bound (the sum of its runs') or the memory limit."""
        run = _run_fn_batch(self.run_fn)
        specs, seqs = [spec for _, spec in batch], [seq for seq, _ in batch]
        bounds = [run_time_bound_s(spec, self.timeout_s) for spec in specs]
        bound_s = None if None in bounds else sum(bounds)
        limit_mb = self.memory_limit_mb
        import threading

        pid = os.getpid()
        base_mb = rss_mb(pid) if limit_mb is not None else None
        if base_mb is None:
            limit_mb = None  # no /proc: the memory is not known
        if ((bound_s is None and limit_mb is None) or not hasattr(signal, "setitimer")
                or threading.current_thread() is not threading.main_thread()):
            return answer(batch, run(specs, seqs, worker="inline"), "inline")
        t0 = time.monotonic()

        def guard(signum, frame):
            if bound_s is not None and time.monotonic() - t0 >= bound_s:
                raise _OverTime()
            if limit_mb is not None:
                now_mb = rss_mb(pid)
                if now_mb is not None and now_mb - base_mb > limit_mb:
                    raise _OverMemory(now_mb - base_mb)

        previous = signal.signal(signal.SIGALRM, guard)
        outer = (0.0, 0.0)
        spec, seq = batch[0][1], batch[0][0]
        try:
            # The first alarm at the time bound when it comes before the first poll.
            first = min(bound_s, _GUARD_POLL_S) if limit_mb is not None and bound_s is not None \
                else (bound_s if limit_mb is None else _GUARD_POLL_S)
            outer = signal.setitimer(signal.ITIMER_REAL, first, _GUARD_POLL_S)
            try:
                return answer(batch, run(specs, seqs, worker="inline"), "inline")
            finally:
                signal.setitimer(signal.ITIMER_REAL, 0)
        except _OverTime:
            if len(batch) > 1:
                return None
            return [RunResult.unfinished(spec, "timeout", f"run exceeded the {bound_s:g} s timeout",
                                         time.monotonic() - t0, seq=seq, worker="inline")]
        except _OverMemory as over:
            if len(batch) > 1:
                return None
            return [RunResult.unfinished(spec, "memory", f"resident memory grew {over.grown_mb:.0f} MB in the run, "
                                         f"over the {limit_mb:.0f} MB limit", time.monotonic() - t0, seq=seq,
                                         worker="inline")]
        finally:
            signal.signal(signal.SIGALRM, previous)
            if outer[0] > 0:  # an alarm the caller had set (pytest-timeout's): it goes on, less the run's time
                signal.setitimer(signal.ITIMER_REAL, max(outer[0] - (time.monotonic() - t0), 1e-6), outer[1])

    def close(self) -> None:
        pass


def _die_with_parent() -> None:
    """Linux: SIGKILL this worker when its parent dies, so a killed coordinator leaves no
    worker burning CPU on a run nobody will record."""
    if not sys.platform.startswith("linux"):
        return
    try:
        import ctypes

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except OSError:
        pass


def _worker_main(conn, memory_limit_mb: float | None, run_fn=None) -> None:
    _die_with_parent()
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the coordinator's to handle
    plans = {}
    name = f"pid{os.getpid()}"
    while True:
        try:
            msg = conn.recv()
        except (EOFError, OSError):
            return
        # ("run", [(seq, plan token, spec fields), ...], {token: plan} new to this worker,
        # [tokens to forget]): a batch, stepped together, in one message. The coordinator
        # decides what this worker keeps (`_Worker.plans` mirrors `plans`).
        _, runs, new_plans, forget = msg
        plans.update(new_plans)
        for token in forget:
            plans.pop(token, None)
        specs = [RunSpec.model_construct(plan=plans[token], **fields) for _, token, fields in runs]
        seqs = [seq for seq, _, _ in runs]
        try:
            records = _run_fn_batch(run_fn)(specs, seqs, worker=name)
        except Exception as exc:  # noqa: BLE001 - run_spec catches its own; this guards a custom run_fn
            records = [RunResult.unfinished(spec, "crashed", f"{type(exc).__name__}: {exc}", 0.0, seq=seq,
                                            worker=name) for spec, seq in zip(specs, seqs)]
        # A spike between the coordinator's RSS polls still shows in the peak.
        peak_mb = peak_rss_mb()
        over = bool(memory_limit_mb and peak_mb > memory_limit_mb)
        if over:
            for record in records:
                record.status = "memory"
                record.error = f"peak resident memory {peak_mb:.0f} MB over the {memory_limit_mb:.0f} MB limit"
        try:
            conn.send(records)
        except (BrokenPipeError, OSError):
            return
        if over:
            return  # the peak stays high for the rest of this process: retire


@dataclass(eq=False)
class _Worker:
    process: object
    conn: object
    plans: dict = field(default_factory=dict)  # plan tokens the worker holds, least recently used first
    tasks: int = 0
    job: tuple | None = None  # ([(seq, spec), ...], started_at, time bound [s])
    server: int | None = None  # pid of the forkserver it was forked from (its parent)


SPAWN_ATTEMPTS = 5  # starts of a worker, each on a new forkserver if the last one died


class WorkerStartError(ToolError):
    """No worker process can be started (message for the user)."""


# The forkserver's state lives in `multiprocessing.forkserver._forkserver` (no public API):
# its pid, read to tell a worker lost with its server from one that crashed, and reset when
# the server is gone so that the next start launches a new one.
def _forkserver_pid() -> int | None:
    from multiprocessing import forkserver

    return getattr(forkserver._forkserver, "_forkserver_pid", None)


def _process_gone(pid: int) -> bool:
    """Whether `pid` has exited (Linux /proc: no entry, or a zombie; elsewhere: signal 0)."""
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] in ("Z", "X")
    except (OSError, IndexError):
        if sys.platform.startswith("linux"):
            return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    except OSError:
        return False
    return False


def _server_lost(server: int | None) -> bool:
    """Whether the forkserver a worker was forked from is gone (killed, or replaced since)."""
    return server is not None and (_forkserver_pid() != server or _process_gone(server))


def _forget_dead_forkserver() -> None:
    """Reset multiprocessing's record of a forkserver that can no longer be reaped by it (reaped
    elsewhere), so that the next start launches a new one; a live or reapable one is left to
    `ensure_running`, which restarts a dead server itself."""
    from multiprocessing import forkserver

    server = forkserver._forkserver
    pid = getattr(server, "_forkserver_pid", None)
    if pid is None:
        return
    try:  # WNOWAIT: look without reaping (ensure_running reaps it and starts a new one)
        os.waitid(os.P_PID, pid, os.WEXITED | os.WNOHANG | os.WNOWAIT)
        return
    except ChildProcessError:
        pass
    with server._lock:
        fd, server._forkserver_alive_fd = server._forkserver_alive_fd, None
        server._forkserver_pid = server._forkserver_address = None
        if fd is not None:
            with contextlib.suppress(OSError):
                os.close(fd)


class LocalExecutor:
    """Long-lived worker processes on this machine, with per-run timeout and memory guard.

    `timeout_s`: wall-clock seconds a run may take before it is killed: "auto" (default) a
    bound derived from the scenario (`run_time_bound_s`), a number, or None / 0 (no limit).
    `retries`: how often a run that did not finish is run again (`Attempts`).
    `memory_limit_mb`: resident memory a worker may use (None: no limit); checked while a
    run is in flight and against the worker's peak when it finishes.
    `run_fn`: what a worker calls per run (default `run_spec`; a module-level function
    with the same signature, e.g. to test the guards); one with a `run_batch(specs, seqs,
    worker)` is handed whole batches (the search's `Judge`).
    `keep_workers`: keep the idle workers between `imap` calls until `close()` (the search
    calls `imap` once per small batch; starting two workers per batch cost more than the
    runs themselves).
    `batch`: runs a worker steps together (`execute_batch`; a run's record does not depend
    on its batch). A batch's time bound is the sum of its runs' bounds. A batch that does
    not finish (past its bound, over the memory limit, its worker crashed or killed) is
    not judged: each of its runs goes again alone, under its own bound and the retry policy,
    so one hung or crashing run costs the others a rerun, never their records.
    """

    name = "local"

    def __init__(self, jobs: int = 1, timeout_s: float | str | None = AUTO,
                 memory_limit_mb: float | None = DEFAULT_MEMORY_LIMIT_MB,
                 max_tasks_per_child: int | None = DEFAULT_MAX_TASKS_PER_CHILD,
                 start_method: str | None = None, run_fn: Callable | None = None,
                 retries: int = DEFAULT_RETRIES, keep_workers: bool = False, batch: int = 1):
        self.workers = max(1, int(jobs))
        self.batch = max(1, int(batch))
        self.keep_workers = keep_workers
        self._kept: list[_Worker] = []  # idle workers kept from the last `imap` (keep_workers)
        self.timeout_s = timeout_s if timeout_s == AUTO or (timeout_s and timeout_s > 0) else None
        self.retries = retries
        self.retried = 0  # runs run again, after `imap`
        self.memory_limit_mb = memory_limit_mb if memory_limit_mb and memory_limit_mb > 0 else None
        self.max_tasks_per_child = max_tasks_per_child if max_tasks_per_child and max_tasks_per_child > 0 else None
        if start_method is None:
            # forkserver: workers fork from a clean server that imported the runtime once, so
            # starting or replacing one is cheap and never inherits the caller's threads.
            start_method = "forkserver" if "forkserver" in mp.get_all_start_methods() else "spawn"
        self.start_method = start_method
        self.run_fn = run_fn
        # id(plan) -> (token, plan), least recently used first, at most PLANS_KEPT: the plan is
        # held so its id is not reused while registered; tokens are never reused.
        self._plans: dict[int, tuple[int, object]] = {}
        self._tokens = itertools.count()

    def _context(self):
        ctx = mp.get_context(self.start_method)
        if self.start_method == "forkserver":
            # The server imports the runtime (and the module of a custom run_fn, e.g. the
            # search's judge) once; every worker forks from it with both loaded. Each worker
            # also runs the caller's main module again (multiprocessing's `prepare`; Python
            # 3.11's forkserver never preloads `__main__`), ~300 ms a worker start with
            # `addtc` as main. Not every module this process has: one that loads torch (the
            # learned stack, here or in a test session) would sit in every worker's memory,
            # past `--memory-limit`'s budget for a run.
            preload = list(WORKER_PRELOAD)
            if self.run_fn is not None:
                preload.append(type(self.run_fn).__module__ if not hasattr(self.run_fn, "__code__")
                               else self.run_fn.__module__)
            ctx.set_forkserver_preload(preload)
        return ctx

    def _spawn(self, ctx) -> _Worker:
        """A new worker. A forkserver killed from outside (it dies while forking this worker:
        `EOFError` where its pid should be) is started again and the worker with it."""
        for attempt in range(SPAWN_ATTEMPTS):
            parent, child = ctx.Pipe(duplex=True)
            process = ctx.Process(target=_worker_main, args=(child, self.memory_limit_mb, self.run_fn),
                                  daemon=True, name="addt-worker")
            try:
                process.start()
            except (EOFError, OSError) as exc:
                parent.close()
                child.close()
                if self.start_method != "forkserver" or attempt == SPAWN_ATTEMPTS - 1:
                    raise WorkerStartError(f"cannot start a worker process ({type(exc).__name__}: {exc})") from exc
                _forget_dead_forkserver()
                time.sleep(0.1 * (attempt + 1))  # a server killed a moment ago may not be reaped yet
                continue
            child.close()
            return _Worker(process, parent, server=_forkserver_pid() if self.start_method == "forkserver" else None)
        raise AssertionError("unreachable")

    def _dispatch(self, w: _Worker, batch: list[tuple[int, RunSpec]]) -> bool:
        """Hand a batch of runs to an idle worker; False if the worker turned out to be dead
        (it died while idle: its pipe is broken), so the caller replaces it."""
        if not w.process.is_alive():
            return False
        runs, new_plans = [], {}
        for seq, spec in batch:
            token = self._plan_token(spec.plan)
            if token in w.plans:
                w.plans[token] = w.plans.pop(token)  # most recently used
            else:
                w.plans[token] = new_plans[token] = spec.plan
            runs.append((seq, token, spec_fields(spec)))
        used = {token for _, token, _ in runs}
        forget = [t for t in w.plans if t not in used][:max(0, len(w.plans) - PLANS_KEPT)]
        for token in forget:
            del w.plans[token]
        try:
            w.conn.send(("run", runs, new_plans, forget))
        except (BrokenPipeError, ConnectionResetError, EOFError, OSError):
            return False
        bounds = [run_time_bound_s(spec, self.timeout_s) for _, spec in batch]
        w.job = (batch, time.monotonic(), None if None in bounds else sum(bounds))
        return True

    def _plan_token(self, plan) -> int:
        """The token `plan` goes under to the workers (a new one for a plan not registered)."""
        entry = self._plans.pop(id(plan), None)
        if entry is None or entry[1] is not plan:
            entry = (next(self._tokens), plan)
        self._plans[id(plan)] = entry
        while len(self._plans) > PLANS_KEPT:
            del self._plans[next(iter(self._plans))]
        return entry[0]

    @staticmethod
    def _stop(w: _Worker, kill: bool = False) -> None:
        if kill and w.process.is_alive():
            w.process.kill()
        w.conn.close()
        w.process.join(timeout=5)
        if w.process.is_alive():
            w.process.kill()
            # Bounded: a forkserver worker's exit status comes through the server, which may
            # be gone or stopped; the worker itself is killed either way.
            w.process.join(timeout=5)

    def imap(self, items: Iterable[tuple[int, RunSpec]]) -> Iterator[RunResult]:
        ctx = self._context()
        items = iter(items)
        attempts = Attempts(self.retries)
        again: deque[tuple[int, RunSpec]] = deque()  # runs to retry, before new ones
        pool, self._kept = self._kept, []
        # Workers start when a run needs one, never more than the runs: `--jobs 100000` on a
        # sweep of 2 runs starts 2 processes, not 100000.
        idle = list(pool)
        busy: list[_Worker] = []
        exhausted = False

        def replace(w: _Worker) -> _Worker:
            pool.remove(w)
            fresh = self._spawn(ctx)
            pool.append(fresh)
            return fresh

        try:
            while True:
                while (idle or len(pool) < self.workers) and (again or not exhausted):
                    # A run going again (a retry, or a run of a batch that did not finish) goes alone.
                    nxt = [again.popleft()] if again else list(itertools.islice(items, self.batch))
                    if not nxt:
                        exhausted = True
                        break
                    if idle:
                        w = idle.pop()
                    else:
                        w = self._spawn(ctx)
                        pool.append(w)
                    while not self._dispatch(w, nxt):  # died while idle: a new one takes the run
                        self._stop(w, kill=True)
                        w = replace(w)
                    busy.append(w)
                if not busy:
                    break
                guarded = self.timeout_s is not None or self.memory_limit_mb is not None
                ready = set(wait([w.conn for w in busy] + [w.process.sentinel for w in busy],
                                 timeout=_GUARD_POLL_S if guarded else None))
                for w in list(busy):
                    result = self._check(w, ready)
                    if result is None:
                        continue
                    records, retire, unfinished = result
                    batch = w.job[0]
                    busy.remove(w)
                    w.job = None
                    idle.append(replace(w) if retire else w)
                    if unfinished and len(batch) > 1:  # isolated: each run again, alone
                        again.extend(batch)
                        continue
                    for (seq, spec), record in zip(batch, answer(batch, records, f"pid{w.process.pid}")):
                        verdict = attempts.judge(seq, record, unfinished == "external")
                        if verdict == "retry":
                            again.append((seq, spec))
                        else:
                            yield record
        finally:
            for w in pool:
                if self.keep_workers and w.job is None and w.process.is_alive():
                    self._kept.append(w)  # a dead one is found and replaced at its next run
                else:
                    self._stop(w, kill=w.job is not None)
            self.retried = attempts.retried

    def close(self) -> None:
        """Stop the workers kept between `imap` calls (`keep_workers`)."""
        kept, self._kept = self._kept, []
        for w in kept:
            self._stop(w)

    def _check(self, w: _Worker, ready: set) -> tuple[list[RunResult], bool, str] | None:
        """(a record per run of the worker's batch, replace the worker, how the batch did not
        finish: "" it finished, "external" its worker was killed from outside, else "failed")
        once the batch is over; None while it runs on."""
        batch, started, bound_s = w.job
        elapsed = time.monotonic() - started
        worker = f"pid{w.process.pid}"
        size = f" (a batch of {len(batch)})" if len(batch) > 1 else ""

        def each(status: str, why: str) -> list[RunResult]:
            return [RunResult.unfinished(spec, status, why + size, elapsed, seq=seq, worker=worker)
                    for seq, spec in batch]

        if w.conn in ready or w.process.sentinel in ready:
            try:
                records = w.conn.recv() if w.conn.poll() else None
            except (EOFError, OSError):
                records = None
            if records is not None:
                w.tasks += len(records)
                memory = any(r.status == "memory" for r in records)
                retire = memory or (self.max_tasks_per_child and w.tasks >= self.max_tasks_per_child)
                if retire:
                    self._stop(w)
                return records, bool(retire), "failed" if memory else ""
            w.process.join(timeout=5)
            code = w.process.exitcode
            why = f"killed by signal {-code}" if code is not None and code < 0 else f"exited with code {code}"
            external = code is not None and code < 0 and -code in EXTERNAL_SIGNALS
            if _server_lost(w.server):  # it dies with the forkserver it was forked from: infrastructure
                why, external = "lost with the forkserver, which was killed", True
            self._stop(w, kill=True)
            return each("crashed", f"worker process {why} during the run"), True, \
                "external" if external else "failed"
        if self.memory_limit_mb is not None:
            rss = rss_mb(w.process.pid)
            if rss is not None and rss > self.memory_limit_mb:
                self._stop(w, kill=True)
                return each("memory", f"resident memory {rss:.0f} MB over the {self.memory_limit_mb:.0f} MB "
                                      "limit"), True, "failed"
        if bound_s is not None and elapsed > bound_s:
            self._stop(w, kill=True)
            return each("timeout", f"run exceeded the {bound_s:g} s timeout"), True, "failed"
        return None


def local_executor(jobs: int = 1, run_fn: Callable | None = None, **options):
    """In this process for one job (nothing to supervise in parallel), else `jobs` guarded
    local workers: what the search, `--classify`'s golden runs and the studies run on."""
    if jobs <= 1:  # the same bounds in this process (`keep_workers` etc. are a pool's)
        return InlineExecutor(run_fn, timeout_s=options.get("timeout_s", AUTO),
                              memory_limit_mb=options.get("memory_limit_mb", DEFAULT_MEMORY_LIMIT_MB),
                              batch=options.get("batch", 1))
    return LocalExecutor(jobs, run_fn=run_fn, **options)


# ---------------------------------------------------------------------------- coordinator

@dataclass
class SweepOutcome:
    """Counts of one `run_sweep` call (the results themselves are in the store)."""

    total: int = 0  # runs in the sweep
    skipped: int = 0  # already in the store (resumed)
    ran: int = 0  # executed and committed now
    passed: int = 0
    failed: int = 0
    statuses: Counter = field(default_factory=Counter)
    lost: list[RunResult] = field(default_factory=list)  # not done after their retries; not stored


def run_sweep(specs: Iterable[RunSpec], store: ResultStore, executor=None,
              on_record: Callable[[RunResult], None] | None = None, classified: bool = False) -> SweepOutcome:
    """Run every spec the store does not hold yet, committing each as it completes. A run
    the executor lost (status `lost`) is counted, not stored, so a resume runs it again. A
    store that cannot take a run (a full disk: `StoreFull`) stops the sweep at once, the
    workers with it; every run committed before stays. `classified` (the executor
    classifies runs): a stored run without an outcome class runs again to get one."""
    executor = executor or LocalExecutor()
    outcome = SweepOutcome()
    done = store.done(classified=classified)

    def pending():
        for seq, spec in enumerate(specs):
            outcome.total += 1
            if done and (spec.key(), spec.run_id) in done:
                outcome.skipped += 1
                continue
            yield seq, spec

    runs = executor.imap(pending())
    try:
        for record in runs:
            outcome.statuses[record.status] += 1
            if record.status == "lost":
                outcome.lost.append(record)
                continue
            store.add(record)
            outcome.ran += 1
            outcome.passed += record.passed
            outcome.failed += not record.passed
            if on_record:
                on_record(record)
    finally:
        close = getattr(runs, "close", None)
        if close is not None:
            close()  # stops the workers now, also when the store failed
    return outcome


def run_local(specs: Iterable[RunSpec], jobs: int = 1,
              on_result: Callable[[RunResult], None] | None = None, **options) -> list[RunResult]:
    """Run specs on local workers and return their records sorted by run id (no store;
    for small sweeps and tests)."""
    executor = LocalExecutor(jobs, **options)
    records = []
    for record in executor.imap(enumerate(specs)):
        records.append(record)
        if on_result:
            on_result(record)
    records.sort(key=lambda r: r.run_id)
    return records
