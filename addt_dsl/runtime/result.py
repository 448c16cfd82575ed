"""`RunResult`: what one run produced, the one type every stage reads.

`execute()` returns it (with the trace attached), executors send it between processes
(trace dropped), the store keeps it, reports count it and the search judges candidates
by it. Whether a run passed, failed or only warned is decided here and nowhere else.

A failure's identity for the search (`Failure`: oracle plus *mode*, the analogue of
Hypothesis's `interesting_origin`) is read from the same record: every violated hard
oracle carries the mode the search annotated it with (`Verdict.mode`), and a run that did
not finish normally fails `stack_health` with what stopped it as its mode.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from addt_dsl.plan import RunSpec

STACK_HEALTH = "stack_health"


@dataclass
class Verdict:
    """One oracle's verdict on a run. `mode` names the culprit of a violated hard oracle
    when the search judged the run (addt_dsl.search.outcome), else ""."""

    name: str
    severity: str  # hard | warn
    robustness: float
    passed: bool
    first_violation_s: float | None = None
    mode: str = ""


@dataclass(frozen=True)
class Failure:
    """A failure's identity: shrinking keeps it, falsification groups by it."""

    oracle: str
    mode: str
    time_s: float | None  # first violation
    robustness: float

    @property
    def id(self) -> tuple[str, str]:
        return self.oracle, self.mode

    def describe(self) -> str:
        when = f" at {self.time_s:.2f} s" if self.time_s is not None else ""
        return f"{self.oracle} [{self.mode}]{when}"


@dataclass
class RunResult:
    run_id: str
    key: str
    spec_json: str  # the RunSpec without its plan; `ResultStore.spec()` rebuilds it
    params: dict[str, float]
    cell: dict[str, float]
    seed: int
    repeat_index: int
    # ok | detected (from the simulation) | crashed | timeout | memory (the executor stopped
    # or lost the run)
    status: str
    verdicts: list[Verdict]
    error: str = ""
    sim_time_s: float = 0.0
    wall_time_s: float = 0.0
    digest: str = ""
    fault_events: int = 0  # injections in all
    stats: dict = field(default_factory=dict)  # latency summaries (store.trace_stats)
    seq: int = -1  # position in the sweep's expansion order
    worker: str = ""
    session: int = 0
    # Outcome class against the fault-free twin (`addtc --classify`, addt_dsl.runtime.outcome):
    # masked | silent | detected | hazard | error; "" when the run was not classified.
    outcome: str = ""
    injections: dict[int, int] = field(default_factory=dict)  # fault index -> injections
    # fault index -> the values its kind's `drawn_setting` took (bitflip: the flipped bits)
    drawn_values: dict[int, tuple[int, ...]] = field(default_factory=dict)
    trace: object | None = field(default=None, repr=False, compare=False)  # only in the executing process

    # ---- the verdict: the one place that decides pass / fail / warn
    @property
    def failed_verdicts(self) -> list[Verdict]:
        """Violated hard oracles: each fails the run."""
        return [v for v in self.verdicts if v.severity == "hard" and not v.passed]

    @property
    def warned_verdicts(self) -> list[Verdict]:
        """Violated `warn` oracles: reported, never a failure."""
        return [v for v in self.verdicts if v.severity == "warn" and not v.passed]

    @property
    def failed_oracles(self) -> list[str]:
        """Violated hard oracles, then what stopped an abnormal run (`stack_health` for a
        run the stack aborted; the executor's status for one it had to stop)."""
        failed = [v.name for v in self.failed_verdicts]
        if self.status == "detected":
            failed.append(STACK_HEALTH)
        elif self.status != "ok":
            failed.append(self.status)
        return failed

    @property
    def warned_oracles(self) -> list[str]:
        return [v.name for v in self.warned_verdicts]

    @property
    def passed(self) -> bool:
        return not self.failed_oracles

    # ---- what the search reads
    @property
    def robustness(self) -> dict[str, float]:
        return {v.name: v.robustness for v in self.verdicts}

    @property
    def failures(self) -> tuple[Failure, ...]:
        out = [Failure(v.name, v.mode, v.first_violation_s, v.robustness) for v in self.failed_verdicts]
        if self.status == "detected":
            out.append(Failure(STACK_HEALTH, self.error.split(":", 1)[0] or self.status, self.sim_time_s, -math.inf))
        elif self.status != "ok":
            what = self.error.split(":", 1)[0] if self.status == "crashed" else self.status
            out.append(Failure(STACK_HEALTH, f"crash {what}".strip(), None, -math.inf))
        return tuple(out)

    def failure(self, fid: tuple[str, str]) -> Failure | None:
        return next((f for f in self.failures if f.id == fid), None)

    def primary(self) -> Failure | None:
        """The failure to shrink by default: the earliest violation (ties: plan order)."""
        return min(self.failures, key=lambda f: math.inf if f.time_s is None else f.time_s, default=None)

    # ---- construction
    @classmethod
    def unfinished(cls, spec: RunSpec, status: str, error: str, wall_time_s: float, seq: int = -1,
                   worker: str = "", key: str | None = None) -> RunResult:
        """A run that produced no verdicts: stopped or lost by the executor, or crashed."""
        return cls(run_id=spec.run_id, key=key or spec.key(), spec_json=spec_json(spec),
                   params=dict(spec.params), cell=dict(spec.cell), seed=spec.seed,
                   repeat_index=spec.repeat_index, status=status, verdicts=[], error=error,
                   wall_time_s=wall_time_s, seq=seq, worker=worker)


def spec_json(spec: RunSpec) -> str:
    return spec.model_dump_json(exclude={"plan"})
