"""Run many RunSpecs: in this process, or on local worker processes.

Workers are long-lived (imports and pybullet set-up are paid once per worker). Results
are returned sorted by run id, so output does not depend on the worker count; each
result is already fully determined by its RunSpec.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import traceback
from collections.abc import Callable, Iterable

from addt_dsl.plan import RunSpec
from addt_dsl.runtime.execute import RunResult, execute


def _run_one(spec: RunSpec) -> RunResult:
    try:
        return execute(spec, keep_trace=False)
    except Exception as exc:  # noqa: BLE001 - a crashing run is recorded, the sweep goes on
        return RunResult(run_id=spec.run_id, key=spec.key(), params=dict(spec.params), seed=spec.seed,
                         verdicts=[], status="crashed",
                         error=f"{type(exc).__name__}: {exc}\n{traceback.format_exc(limit=3)}",
                         sim_time_s=0.0, wall_time_s=0.0, digest="", fault_events=0,
                         cell=dict(spec.cell))


def run_local(specs: Iterable[RunSpec], jobs: int = 1,
              on_result: Callable[[RunResult], None] | None = None) -> list[RunResult]:
    specs = list(specs)
    results: list[RunResult] = []
    if jobs <= 1 or len(specs) <= 1:
        for spec in specs:
            r = _run_one(spec)
            results.append(r)
            if on_result:
                on_result(r)
    else:
        ctx = mp.get_context("fork" if os.name == "posix" else "spawn")
        with ctx.Pool(processes=jobs, maxtasksperchild=200) as pool:
            for r in pool.imap_unordered(_run_one, specs, chunksize=1):
                results.append(r)
                if on_result:
                    on_result(r)
    results.sort(key=lambda r: r.run_id)
    return results
