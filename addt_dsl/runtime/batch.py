"""The engine: `execute_batch(specs) -> [RunResult]` steps many runs in lockstep.

At each sample k every phase of the step (`phases.py`) runs over the runs still live:
the batch's phases (pose, record, collisions, ego, agents) over all of them at once, the
per-run phases between two of them run by run (environment to end of one run, of the
next, ...); a run leaves the live set where it ends (an ego collision, `end when`, its last sample, a stack
error, a non-finite ego state). A single run is a batch of one (`execute.execute`): there
is no other loop. Runs share nothing but the code: each owns its state (`state.RunState`),
its pybullet client and its random streams (seeded by its RunSpec), so a run's trace is the
same bit for bit alone, beside any other runs, in any order (tests/sim/runtime/test_batch.py).
The phases that are pure numerics run as arrays over the batch: the agents' poses and
their longitudinal step (every live run's agents concatenated: `agents.Fleets`), the
egos' dynamics and recorded rows (every run's ego state a row of one block:
`vehicle.StateBlock`); behaviours, sensors, triggers and the stack step per run.
"""

from __future__ import annotations

import time as _time
from collections import Counter
from typing import Sequence

from addt_dsl.plan import RunSpec
from addt_dsl.registry import FAULTS
from addt_dsl.runtime import phases
from addt_dsl.runtime.agents import Fleets
from addt_dsl.runtime.judge import judge
from addt_dsl.runtime.result import RunResult, spec_json
from addt_dsl.runtime.state import RunState
from addt_dsl.runtime.trace import Event, Trace, injection_count
from addt_dsl.runtime.vehicle import StateBlock


def execute_batch(specs: Sequence[RunSpec], keep_trace: bool = True) -> list[RunResult]:
    """Run each RunSpec closed-loop, all stepped together, and judge each; in `specs` order.

    A set-up failure of any run (e.g. an unreachable external stack) raises, as `execute`
    does for one: callers that want the others isolate by running the batch's runs alone
    (`executor.run_batch`). Each result's `wall_time_s` is its own set-up and judging time
    plus its share of the shared loop (the loop's time over the samples each run stepped).
    """
    runs: list[RunState] = []
    setup: list[float] = []
    roads: dict = {}  # road networks and views, shared by runs of equal road plans
    try:
        for spec in specs:
            t0 = _time.perf_counter()
            runs.append(RunState(spec, roads))
            setup.append(_time.perf_counter() - t0)
        t0 = _time.perf_counter()
        traces = _loop(runs)
        loop_s = _time.perf_counter() - t0
    finally:
        for run in runs:
            run.close()
    steps = sum(len(tr.time) for tr in traces) or 1
    out = []
    for run, trace, own_s in zip(runs, traces, setup):
        t0 = _time.perf_counter()
        result = _result(run, trace, keep_trace)
        result.wall_time_s = own_s + loop_s * len(trace.time) / steps + _time.perf_counter() - t0
        out.append(result)
    return out


def _result(run: RunState, trace: Trace, keep_trace: bool) -> RunResult:
    """The judged record of one run."""
    spec = run.spec
    verdicts = judge(run.bound, trace)
    injections: Counter = Counter()
    drawn_name = {f.index: FAULTS.get(f.kind).drawn_setting for f in spec.faults}
    drawn: dict[int, list[int]] = {}
    for e in trace.events:
        if e.kind == "fault":
            index = e.detail["index"]
            injections[index] += injection_count(e)
            name = drawn_name.get(index)
            if name is not None and name in e.detail:
                drawn.setdefault(index, []).append(int(e.detail[name]))
    return RunResult(
        run_id=spec.run_id, key=spec.key(), spec_json=spec_json(spec), params=dict(spec.params),
        cell=dict(spec.cell), seed=spec.seed, repeat_index=spec.repeat_index, status=trace.status,
        verdicts=verdicts, error=trace.error, sim_time_s=trace.duration_s,
        wall_time_s=0.0, digest=trace.digest(), fault_events=sum(injections.values()),
        injections=dict(injections), drawn_values={k: tuple(v) for k, v in drawn.items()},
        trace=trace if keep_trace else None)


def _stop(run: RunState, rec: phases.Record, k: int, error: str, t: float | None = None) -> None:
    """A run stops on a failure at sample k (`detected`, why; a stack error's event)."""
    run.status, run.error = "detected", error
    if t is not None:
        run.events.append(Event(t, "stack_error", {"error": error}))
    rec.last = k + 1


def _loop(runs: list[RunState]) -> list[Trace]:
    """Step every run from time 0 until its end, an ego collision or a failure; their traces."""
    recs = phases.Record.batch(runs)
    fleets = Fleets(runs)  # the agents of every run in one block of arrays
    egos = StateBlock([run.ego for run in runs], [run.dt for run in runs])  # every ego's state: one block
    for i, run in enumerate(runs):
        run.ego_row = i
    live = list(zip(runs, recs))
    k = 0
    while live:
        # Each phase over the live runs, in the documented order (runs share nothing: each
        # run's phases in that order is all that matters).
        lruns, lrecs = [run for run, _ in live], [rec for _, rec in live]
        ts = [k * run.dt for run in lruns]
        phases.clock(lruns, ts)
        phases.pose(lruns, ts, fleets, egos)
        phases.record(lruns, lrecs, k, egos, fleets)
        collided = phases.collisions(lruns, lrecs, k, ts)
        phases.environment(lruns, lrecs, k, ts)
        phases.variables(lruns, lrecs, k, ts)
        phases.lights(lruns, lrecs, k, ts)
        phases.outputs(lruns, lrecs, k, ts)
        ended = phases.end(lruns, lrecs, k, ts)
        going, going_recs, going_ts = [], [], []
        for run, rec, t, hit, done in zip(lruns, lrecs, ts, collided, ended):
            if hit or done or k == rec.n - 1:
                rec.last = k + 1
            else:
                going.append(run)
                going_recs.append(rec)
                going_ts.append(t)
        phases.conditions(going, going_recs, k)
        phases.triggers(going, going_recs, k, going_ts)
        fed, fed_ts = [], []
        for run, rec, t, exc in zip(going, going_recs, going_ts, phases.sense(going, going_ts)):
            if exc is not None:
                _stop(run, rec, k, f"{type(exc).__name__}: {exc}", t)
                continue
            fed.append((run, rec))
            fed_ts.append(t)
        sensed, sensed_runs, sensed_ts = [], [], []
        for (run, rec), t, exc in zip(fed, fed_ts, phases.stack([run for run, _ in fed], fed_ts)):
            if exc is not None:
                _stop(run, rec, k, f"{type(exc).__name__}: {exc}", t)
                continue
            sensed.append((run, rec))
            sensed_runs.append(run)
            sensed_ts.append(t)
        moved = phases.ego(sensed_runs, sensed_ts, egos)
        if all(moved):
            live = sensed
        else:
            live = []
            for (run, rec), finite in zip(sensed, moved):
                if finite:
                    live.append((run, rec))
                else:
                    _stop(run, rec, k, "vehicle state became non-finite")
            sensed_ts = [t for (run, _), t, finite in zip(sensed, sensed_ts, moved) if finite]
        phases.agents([run for run, _ in live], sensed_ts, fleets)
        k += 1
    return [rec.trace(run) for run, rec in zip(runs, recs)]
