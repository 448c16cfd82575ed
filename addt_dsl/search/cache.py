"""Run cache keyed by `RunSpec.key()`: the search never simulates one candidate twice.

A RunSpec determines its run, so its result is a pure function of its key. The cache is
a results store (`ResultStore.cache`: in memory, or a file given a path, so a second
`addtc shrink` or a CI re-run of the same failure replays nothing it has seen) and its
misses run on the executors sweeps use: in this process for one job, else on supervised
local workers (timeout, memory and crash guards of `LocalExecutor`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from pathlib import Path

from addt_dsl.errors import ToolError
from addt_dsl.plan import RunSpec
from addt_dsl.runtime.executor import batch_size, local_executor
from addt_dsl.runtime.result import RunResult
from addt_dsl.runtime.store import ResultStore, StoreBusy, StoreError
from addt_dsl.search.outcome import evaluate


class Judge:
    """What an executor's worker runs for the search: `evaluator(spec)` (default
    `search.outcome.evaluate`), a module-level function so workers can be handed it.
    Executors hand it batches (`run_batch`): an evaluator with a batched form
    (`evaluator.batched(specs)`, e.g. `evaluate_batch`) steps them together, any other
    judges them one by one."""

    def __init__(self, evaluator: Callable[[RunSpec], RunResult] = evaluate):
        self.evaluator = evaluator

    def __call__(self, spec: RunSpec, seq: int = -1, worker: str = "") -> RunResult:
        return self.run_batch([spec], [seq], worker)[0]

    def run_batch(self, specs: list[RunSpec], seqs: list[int], worker: str = "") -> list[RunResult]:
        batched = getattr(self.evaluator, "batched", None)
        results = batched(specs) if batched is not None and len(specs) > 1 else [self.evaluator(s) for s in specs]
        for result, seq in zip(results, seqs):
            result.seq, result.worker, result.trace = seq, worker, None
        return results


class RunCache:
    _store: ResultStore | None = None

    def __init__(self, path: str | Path | None = None, evaluator: Callable[[RunSpec], RunResult] = evaluate,
                 batch: int | None = None):
        self.judge = Judge(evaluator)
        # Misses a worker steps together (the batch engine); None: `batch_size` of each call's misses.
        self.batch = batch
        self.path = Path(path) if path is not None else None
        if self.path is not None and self.path.exists():
            self.store  # a file that is no store is refused now, not at the first run
        self.results: dict[str, RunResult] = {}
        self.hits = 0
        self.simulations = 0
        self._executors: dict = {}  # jobs -> executor with kept workers (`_executor`)

    @property
    def store(self) -> ResultStore:
        """The cache's store, opened (and locked: one writer) when first needed, so a
        command refused for a bad option leaves no cache file behind."""
        if self._store is None:
            try:
                self._store = ResultStore.cache(self.path)
            except StoreError as exc:
                if isinstance(exc, StoreBusy) or "not a results store" not in str(exc):
                    raise
                raise ValueError(f"{self.path} is not a results store; earlier versions kept run caches as "
                                 "JSON lines: remove the file or pick another --cache") from None
        return self._store

    def _lookup(self, key: str) -> RunResult | None:
        if key not in self.results:
            found = self.store.find(key)
            if found is None:
                return None
            self.results[key] = found
        return self.results[key]

    def __contains__(self, spec: RunSpec) -> bool:
        return self._lookup(spec.key()) is not None

    def get(self, spec: RunSpec) -> RunResult:
        return self.get_many([spec])[0]

    def get_many(self, specs: Iterable[RunSpec], jobs: int = 1) -> list[RunResult]:
        """Results in order; the misses run on `jobs` supervised local workers."""
        specs = list(specs)
        keys = [s.key() for s in specs]
        todo: dict[str, RunSpec] = {}
        for k, s in zip(keys, specs):
            if k in todo or self._lookup(k) is not None:
                self.hits += 1
            else:
                todo[k] = s
        if todo:
            executor = self._executor(min(jobs, len(todo)))
            executor.batch = self.batch or batch_size(len(todo), executor.workers)
            pending = list(todo.values())
            pending_keys = list(todo)
            answered = set()
            for result in executor.imap(enumerate(pending)):
                if result.status == "lost":  # never a verdict: the search cannot go on without it
                    raise ToolError(f"candidate {result.run_id or result.key} could not be run ({result.error}); "
                                    "run the same command again: every run so far is kept"
                                    + (f" in {self.path}" if self.path else ""))
                # Filed under the key of the run asked for (its seq), never one the worker computed.
                key = pending_keys[result.seq]
                result.key = key
                self.store.add(result, pending[result.seq].plan)
                self.results[key] = result
                answered.add(key)
            if len(answered) != len(todo):
                raise ToolError(f"{len(todo) - len(answered)} of {len(todo)} candidate(s) came back without a "
                                "result; run the same command again: every run so far is kept"
                                + (f" in {self.path}" if self.path else ""))
            self.simulations += len(todo)
        return [self.results[k] for k in keys]

    def _executor(self, jobs: int):
        """One executor per job count, its workers kept between calls: a search judges a
        handful of candidates per call, and starting workers each time cost more than
        running them (1.2 s against 0.2 s per run, measured on a loaded 2-core machine)."""
        if jobs not in self._executors:
            self._executors[jobs] = local_executor(jobs, self.judge, keep_workers=True)
        return self._executors[jobs]

    def release_workers(self) -> None:
        """Stop the kept workers (a search calls this when it ends; the next call starts new ones)."""
        for executor in self._executors.values():
            executor.close()
        self._executors.clear()

    def close(self) -> None:
        self.release_workers()
        if self._store is not None:
            self._store.close()
