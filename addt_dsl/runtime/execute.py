"""`execute(RunSpec) -> RunResult`: the only entry point into the runtime.

A batch of one: the engine (`batch.execute_batch`) steps many runs in lockstep over their
states (`state.RunState`); each sample runs the step's named phases (`phases.py`: pose,
record, lights, collisions, triggers, sense, stack, ego dynamics, agents) in order.
Behaviours, sensors and the stack see the world only through the declared interfaces
(`views.py`). Everything random draws from
generators seeded by the RunSpec, so the same RunSpec gives the same trace bit for bit.
"""

from __future__ import annotations

from addt_dsl.plan import RunSpec
from addt_dsl.runtime.batch import execute_batch
from addt_dsl.runtime.result import RunResult

__all__ = ["execute", "execute_batch"]


def execute(spec: RunSpec, keep_trace: bool = True) -> RunResult:
    """Run one RunSpec closed-loop and judge it: a batch of one (`batch.execute_batch`)."""
    return execute_batch([spec], keep_trace)[0]
