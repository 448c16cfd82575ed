"""Run a sweep on a Ray cluster: `addtc FILE --executor ray [--address ADDR]`.

Each task steps a batch of runs (`batch`, default 1) with the same `run_batch` as a local
worker, so a record is the same wherever and beside whatever it ran. The plan goes to the
object store once (`ray.put`); tasks carry only the RunSpecs' own fields. At most one task
per CPU slot is in flight, so a task starts about when it is submitted and the coordinator
holds only those few batches.

Guards: a run past its time bound (`timeout_s`, by default derived from the scenario:
`executor.run_time_bound_s`, counted from submission) is cancelled with `force=True`,
which kills its worker, and recorded as `timeout`; a run whose worker ends above
`memory_limit_mb`, or that Ray's own memory monitor kills, is recorded as `memory`.
Retries follow the local executor's policy (`executor.Attempts`), applied here rather than
with Ray's `max_retries` so that every attempt gets its own time bound: a task whose
worker or node was lost (any other `RayError`) is infrastructure and is submitted again up
to `retries` times, then reported `lost` (not stored); a run that failed the same way twice
is recorded. A batch's bound is the sum of its runs'; a batch that did not finish is not
judged: each of its runs is submitted again alone (as `LocalExecutor` isolates them).
Workers are recycled after `max_tasks_per_child` tasks (Ray's `max_calls`).
Ray is optional: `pip install 'addt-dsl[ray]'`.
"""

from __future__ import annotations

import importlib.util
import itertools
import os
import time
from collections import deque
from collections.abc import Iterable, Iterator

from addt_dsl.plan import RunSpec
from addt_dsl.runtime.executor import (AUTO, DEFAULT_MAX_TASKS_PER_CHILD, DEFAULT_MEMORY_LIMIT_MB,
                                       DEFAULT_RETRIES, Attempts, answer, rss_mb, run_batch, run_time_bound_s,
                                       spec_fields)
from addt_dsl.runtime.result import RunResult

_POLL_S = 0.2


def ray_available() -> bool:
    return importlib.util.find_spec("ray") is not None


def _ray_task(runs: list, memory_limit_mb: float | None) -> list[RunResult]:
    """[(plan's object ref, spec fields, seq), ...] stepped together: a record each (refs
    nested in a list are not resolved by Ray: fetched here, once per plan)."""
    import ray

    plans: dict = {}
    specs = []
    for ref, fields, _ in runs:
        if ref not in plans:
            plans[ref] = ray.get(ref)
        specs.append(RunSpec.model_construct(plan=plans[ref], **fields))
    records = run_batch(specs, [seq for _, _, seq in runs], worker=f"ray-pid{os.getpid()}")
    # Ray reuses workers, so a peak from an earlier task would stay; judge the current size.
    rss = rss_mb(os.getpid())
    if memory_limit_mb and rss is not None and rss > memory_limit_mb:
        for record in records:
            record.status = "memory"
            record.error = f"resident memory {rss:.0f} MB over the {memory_limit_mb:.0f} MB limit"
    return records


class RayExecutor:
    name = "ray"

    def __init__(self, address: str | None = None, jobs: int | None = None, timeout_s: float | str | None = AUTO,
                 memory_limit_mb: float | None = DEFAULT_MEMORY_LIMIT_MB,
                 max_tasks_per_child: int | None = DEFAULT_MAX_TASKS_PER_CHILD, init_kwargs: dict | None = None,
                 retries: int = DEFAULT_RETRIES, batch: int = 1):
        self.address = address
        self.batch = max(1, int(batch))
        self.jobs = jobs
        self.timeout_s = timeout_s if timeout_s == AUTO or (timeout_s and timeout_s > 0) else None
        self.retries = retries
        self.retried = 0
        self.memory_limit_mb = memory_limit_mb if memory_limit_mb and memory_limit_mb > 0 else None
        self.max_tasks_per_child = max_tasks_per_child or 0
        self.init_kwargs = init_kwargs or {}
        self.workers = jobs or 0

    def _init(self):
        import ray

        if ray.is_initialized():
            return False
        kwargs = {"include_dashboard": False, "log_to_driver": False, **self.init_kwargs}
        if self.address:
            kwargs["address"] = self.address
        elif self.jobs:
            kwargs.setdefault("num_cpus", self.jobs)
        ray.init(**kwargs)
        return True

    def imap(self, items: Iterable[tuple[int, RunSpec]]) -> Iterator[RunResult]:
        import ray
        from ray import exceptions as rex

        started_here = self._init()
        try:
            slots = self.jobs or max(1, int(ray.cluster_resources().get("CPU", 1)))
            self.workers = slots
            options = {"num_cpus": 1, "max_retries": 0}  # retried here, each attempt bounded (Attempts)
            if self.max_tasks_per_child:
                options["max_calls"] = self.max_tasks_per_child
            task = ray.remote(**options)(_ray_task)
            plan_refs: dict[int, tuple[object, object]] = {}  # id(plan) -> (plan, ref): keeps ids unique
            inflight: dict[object, tuple[list[tuple[int, RunSpec]], float, float | None]] = {}
            attempts = Attempts(self.retries)
            again: deque[tuple[int, RunSpec]] = deque()
            items = iter(items)
            exhausted = False
            while True:
                while (again or not exhausted) and len(inflight) < slots:
                    # A run going again (a retry, or a run of a batch that did not finish) goes alone.
                    batch = [again.popleft()] if again else list(itertools.islice(items, self.batch))
                    if not batch:
                        exhausted = True
                        break
                    runs = []
                    for seq, spec in batch:
                        _, plan_ref = plan_refs.setdefault(id(spec.plan), (spec.plan, ray.put(spec.plan)))
                        runs.append((plan_ref, spec_fields(spec), seq))
                    ref = task.remote(runs, self.memory_limit_mb)
                    bounds = [run_time_bound_s(spec, self.timeout_s) for _, spec in batch]
                    inflight[ref] = (batch, time.monotonic(), None if None in bounds else sum(bounds))
                if not inflight:
                    break
                ready, _ = ray.wait(list(inflight), num_returns=1,
                                    timeout=_POLL_S if self.timeout_s else None)
                finished = []  # (batch, records, external, finished as a batch)
                for ref in ready:
                    batch, started, _ = inflight.pop(ref)
                    elapsed = time.monotonic() - started

                    def each(status, why, _batch=batch, _elapsed=elapsed):
                        return [RunResult.unfinished(spec, status, why, _elapsed, seq=seq) for seq, spec in _batch]

                    try:
                        records = ray.get(ref)
                        done = not any(r.status == "memory" for r in records)
                        finished.append((batch, records, False, done))
                    except rex.OutOfMemoryError as exc:
                        finished.append((batch, each("memory", f"Ray killed the task: {exc}"), False, False))
                    except rex.RayError as exc:  # the worker or its node was lost: infrastructure
                        first = (str(exc).splitlines() or [""])[0]
                        finished.append((batch, each("crashed", f"{type(exc).__name__}: {first}"), True, False))
                now = time.monotonic()
                for ref, (batch, started, bound_s) in list(inflight.items()):
                    if bound_s is not None and now - started > bound_s:
                        ray.cancel(ref, force=True)
                        del inflight[ref]
                        finished.append((batch, [RunResult.unfinished(
                            spec, "timeout", f"run exceeded the {bound_s:g} s timeout", now - started, seq=seq)
                            for seq, spec in batch], False, False))
                for batch, records, external, done in finished:
                    if not done and len(batch) > 1:  # isolated: each run again, alone
                        again.extend(batch)
                        continue
                    for (seq, spec), record in zip(batch, answer(batch, records, "ray")):
                        verdict = attempts.judge(seq, record, external)
                        if verdict == "retry":
                            again.append((seq, spec))
                        else:
                            yield record
            self.retried = attempts.retried
        finally:
            if started_here:
                ray.shutdown()
