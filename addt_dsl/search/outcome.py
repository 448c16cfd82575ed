"""What a run tells the search: verdicts, robustness and the identity of each failure.

A failure's identity is its oracle plus its *mode*, the analogue of Hypothesis's
`interesting_origin` (exception type and location): the atomic comparison of the
oracle's formula that was worst at the first violation time, refined by what the
trace says about it (`MODE_REFINERS`: whom the ego hit, which side it left its lane
on). Shrinking keeps the identity, so a collision with the lead never "shrinks" into a
collision with the truck, nor a departure to the left into one to the right.
A run the stack aborts (exception, non-finite command) fails `stack_health` with the
error type as its mode.
"""

from __future__ import annotations

import math
import time
import traceback
from collections import Counter
from dataclasses import asdict, dataclass, field

import numpy as np

from addt_dsl import expr as E
from addt_dsl.plan import RunSpec

STACK_HEALTH = "stack_health"


@dataclass(frozen=True)
class Failure:
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
class Outcome:
    """A run as the search sees it (no trace: cheap to cache and to send between processes)."""

    key: str
    status: str  # ok | detected | crashed
    error: str
    robustness: dict[str, float]  # every oracle, hard and warn
    hard: tuple[str, ...]  # names of the hard oracles
    failures: tuple[Failure, ...]  # hard oracles that failed (and stack_health)
    fault_events: dict[int, int] = field(default_factory=dict)  # fault index -> injections
    flipped_bits: dict[int, tuple[int, ...]] = field(default_factory=dict)  # bitflip index -> bits
    digest: str = ""
    wall_time_s: float = 0.0

    @property
    def passed(self) -> bool:
        return not self.failures

    def failure(self, fid: tuple[str, str]) -> Failure | None:
        return next((f for f in self.failures if f.id == fid), None)

    def primary(self) -> Failure | None:
        """The failure to shrink by default: the earliest violation (ties: plan order)."""
        if not self.failures:
            return None
        return min(self.failures, key=lambda f: math.inf if f.time_s is None else f.time_s)

    def to_json(self) -> dict:
        data = asdict(self)
        data["failures"] = [asdict(f) for f in self.failures]
        data["fault_events"] = {str(k): v for k, v in self.fault_events.items()}
        data["flipped_bits"] = {str(k): list(v) for k, v in self.flipped_bits.items()}
        data["robustness"] = {k: _finite_or_str(v) for k, v in self.robustness.items()}
        return data

    @classmethod
    def from_json(cls, data: dict) -> Outcome:
        return cls(key=data["key"], status=data["status"], error=data["error"],
                   robustness={k: float(v) for k, v in data["robustness"].items()},
                   hard=tuple(data["hard"]),
                   failures=tuple(Failure(f["oracle"], f["mode"], f["time_s"], float(f["robustness"]))
                                  for f in data["failures"]),
                   fault_events={int(k): v for k, v in data["fault_events"].items()},
                   flipped_bits={int(k): tuple(v) for k, v in data["flipped_bits"].items()},
                   digest=data.get("digest", ""), wall_time_s=data.get("wall_time_s", 0.0))


def _finite_or_str(x: float):
    return x if math.isfinite(x) else repr(x)


# ---------------------------------------------------------------- evaluation

def evaluate(spec: RunSpec, keep_trace: bool = False):
    """Run `spec` and judge it: `Outcome`, or `(Outcome, Trace)` with `keep_trace`."""
    from addt_dsl.runtime.execute import execute

    wall0 = time.perf_counter()
    hard = tuple(o.name for o in spec.plan.oracles if o.severity == "hard")
    try:
        result = execute(spec, keep_trace=True)
    except Exception as exc:  # noqa: BLE001 - a crashing run is a finding, not a search error
        outcome = Outcome(spec.key(), "crashed", f"{type(exc).__name__}: {exc}\n{traceback.format_exc(limit=3)}",
                          {}, hard, (Failure(STACK_HEALTH, f"crash {type(exc).__name__}", None, -math.inf),),
                          wall_time_s=time.perf_counter() - wall0)
        return (outcome, None) if keep_trace else outcome
    trace = result.trace
    failures = [Failure(v.name, failure_mode(spec, trace, v.name, v.first_violation_s), v.first_violation_s,
                        v.robustness)
                for v in result.verdicts if v.severity == "hard" and not v.passed]
    if result.status != "ok":
        kind = result.error.split(":", 1)[0] or result.status
        failures.append(Failure(STACK_HEALTH, kind, trace.duration_s, -math.inf))
    from addt_dsl.runtime.trace import injection_count

    events = Counter()
    bits: dict[int, list[int]] = {}
    for e in trace.events:
        if e.kind == "fault":
            events[e.detail["index"]] += injection_count(e)
            if "bit" in e.detail:
                bits.setdefault(e.detail["index"], []).append(int(e.detail["bit"]))
    outcome = Outcome(spec.key(), result.status, result.error, {v.name: v.robustness for v in result.verdicts},
                      hard, tuple(failures), dict(events), {k: tuple(v) for k, v in bits.items()},
                      result.digest, time.perf_counter() - wall0)
    return (outcome, trace) if keep_trace else outcome


# ---------------------------------------------------------------- failure modes

def _atoms(formula) -> list:
    return [n for n in E.walk(formula) if isinstance(n, E.Binary) and n.op in E.COMPARE_OPS]


def _signal_args(name: str) -> tuple[str, tuple[str, ...]]:
    fn, _, rest = name.partition("(")
    return fn, tuple(a for a in rest.rstrip(")").split(",") if a)


def _nearest_other(trace, args, k) -> str:
    me = trace.actors.get(args[0]) if args else None
    if me is None:
        return ""
    best = min(((math.hypot(a.x[k] - me.x[k], a.y[k] - me.y[k]), n) for n, a in trace.actors.items()
                if n != args[0]), default=None)
    return f"with {best[1]}" if best else ""


def _side(trace, args, k) -> str:
    me = trace.actors.get(args[0]) if args else None
    if me is None:
        return ""
    return "left" if me.lane_offset[k] > 0 else "right"


# Signal function -> what to add to the mode when that signal carries the failure.
MODE_REFINERS = {"clearance": _nearest_other, "lane_offset": _side}


def failure_mode(spec: RunSpec, trace, oracle_name: str, time_s: float | None) -> str:
    """The culprit comparison of a failed oracle at its first violation, refined."""
    from addt_dsl.runtime import oracles
    from addt_dsl.runtime.signals import compute_signals

    o = next(o for o in spec.plan.oracles if o.name == oracle_name)
    formula = E.substitute_params(o.formula, spec.params)
    atoms = _atoms(formula)
    if not atoms:
        return "formula"
    n = len(trace.time)
    k = min(n - 1, max(0, int(round((time_s or 0.0) / trace.period_s))))
    signals = compute_signals(trace, E.signals_used(formula))
    worst, worst_rho = atoms[0], math.inf
    for atom in atoms:
        rho = float(np.asarray(oracles.evaluate(atom, signals, trace.period_s))[k])
        if rho < worst_rho:
            worst, worst_rho = atom, rho
    text = _atom_text(spec, worst)
    notes = []
    for name in sorted(E.signals_used(worst)):
        fn, args = _signal_args(name)
        refine = MODE_REFINERS.get(fn)
        if refine is not None:
            note = refine(trace, args, k)
            if note:
                notes.append(note)
    return text + (f" [{', '.join(notes)}]" if notes else "")


def _atom_text(spec: RunSpec, atom) -> str:
    from addt_dsl.printer import PrinterError, format_expr

    try:
        return format_expr(atom)
    except PrinterError:
        return repr(atom)
