"""`execute(RunSpec) -> RunResult`: the only entry point into the runtime.

One discrete loop in simulated time over the run's state (`state.RunState`): each sample
runs the step's named phases (`phases.py`: pose, record, lights, collisions, triggers,
sense, stack, ego dynamics, agents) in order. Behaviours, sensors and the stack see the
world only through the declared interfaces (`views.py`). Everything random draws from
generators seeded by the RunSpec, so the same RunSpec gives the same trace bit for bit.
"""

from __future__ import annotations

import time as _time
from collections import Counter

from addt_dsl.plan import RunSpec
from addt_dsl.registry import FAULTS
from addt_dsl.runtime import phases
from addt_dsl.runtime.judge import judge
from addt_dsl.runtime.result import RunResult, spec_json
from addt_dsl.runtime.state import RunState
from addt_dsl.runtime.trace import Event, Trace, injection_count


def execute(spec: RunSpec, keep_trace: bool = True) -> RunResult:
    """Run one RunSpec closed-loop and judge it."""
    wall0 = _time.perf_counter()
    run = RunState(spec)
    try:
        trace = _loop(run)
    finally:
        run.close()
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
        wall_time_s=_time.perf_counter() - wall0, digest=trace.digest(), fault_events=sum(injections.values()),
        injections=dict(injections), drawn_values={k: tuple(v) for k, v in drawn.items()},
        trace=trace if keep_trace else None)


def _loop(run: RunState) -> Trace:
    """Step the run from time 0 until its end, an ego collision or a failure; its trace."""
    rec = phases.Record(run)
    n = rec.n
    for k in range(n):
        t = k * run.dt
        phases.clock(run, t)
        phases.pose(run, t)
        phases.record(run, rec, k)
        phases.environment(run, rec, k, t)
        phases.variables(run, rec, k, t)
        phases.lights(run, rec, k, t)
        collided = phases.collisions(run, rec, k, t)
        phases.outputs(run, rec, k, t)
        ended = phases.end(run, rec, k, t)
        if collided or ended or k == n - 1:
            rec.last = k + 1
            break
        phases.triggers(run, rec, k, t)
        try:
            phases.sense(run, t)
            phases.stack(run, t)
        except Exception as exc:  # noqa: BLE001 - a stack failure is an outcome, not a crash
            run.status, run.error = "detected", f"{type(exc).__name__}: {exc}"
            run.events.append(Event(t, "stack_error", {"error": run.error}))
            rec.last = k + 1
            break
        if not phases.ego(run, t):
            run.status, run.error = "detected", "vehicle state became non-finite"
            rec.last = k + 1
            break
        phases.agents(run, t)
    return rec.trace(run)
