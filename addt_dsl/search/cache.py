"""Run cache keyed by `RunSpec.key()`: the search never simulates one candidate twice.

A RunSpec determines its run, so its outcome is a pure function of its key. The cache
lives in memory and, given a path, in an append-only JSON-lines file, so a second
`addtc shrink` (or a CI re-run) of the same failure replays nothing it has seen.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Iterable
from pathlib import Path

from addt_dsl.plan import RunSpec
from addt_dsl.search.outcome import Outcome, evaluate


class RunCache:
    def __init__(self, path: str | Path | None = None, evaluator: Callable[[RunSpec], Outcome] = evaluate):
        self.evaluator = evaluator
        self.path = Path(path) if path else None
        self.outcomes: dict[str, Outcome] = {}
        self.hits = 0
        self.simulations = 0
        self.sim_seconds = 0.0
        if self.path and self.path.is_file():
            for line in self.path.read_text().splitlines():
                try:
                    data = json.loads(line)
                    self.outcomes[data["key"]] = Outcome.from_json(data)
                except (ValueError, KeyError, TypeError):
                    continue  # a torn last line from an interrupted run

    def __contains__(self, spec: RunSpec) -> bool:
        return spec.key() in self.outcomes

    def get(self, spec: RunSpec) -> Outcome:
        key = spec.key()
        if key in self.outcomes:
            self.hits += 1
            return self.outcomes[key]
        t0 = time.perf_counter()
        outcome = self.evaluator(spec)
        self.sim_seconds += time.perf_counter() - t0
        self.simulations += 1
        self._store(outcome)
        return outcome

    def get_many(self, specs: Iterable[RunSpec], jobs: int = 1) -> list[Outcome]:
        """Outcomes in order; the misses run on `jobs` local processes (one result per spec)."""
        specs = list(specs)
        keys = [s.key() for s in specs]
        todo: dict[str, RunSpec] = {}
        for k, s in zip(keys, specs):
            if k in self.outcomes or k in todo:
                self.hits += 1
            else:
                todo[k] = s
        if todo:
            t0 = time.perf_counter()
            for outcome in _run_parallel(list(todo.values()), jobs, self.evaluator):
                self._store(outcome)
            self.sim_seconds += time.perf_counter() - t0
            self.simulations += len(todo)
        return [self.outcomes[k] for k in keys]

    def _store(self, outcome: Outcome) -> None:
        self.outcomes[outcome.key] = outcome
        if self.path:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            with self.path.open("a") as fh:
                fh.write(json.dumps(outcome.to_json()) + "\n")


def _run_parallel(specs: list[RunSpec], jobs: int, evaluator) -> list[Outcome]:
    if jobs <= 1 or len(specs) <= 1:
        return [evaluator(s) for s in specs]
    import multiprocessing as mp
    import os

    ctx = mp.get_context("fork" if os.name == "posix" else "spawn")
    with ctx.Pool(processes=min(jobs, len(specs))) as pool:
        return pool.map(evaluator, specs, chunksize=1)
