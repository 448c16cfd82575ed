"""The verdicts of a run: every oracle of the bound scenario evaluated on its trace."""

from __future__ import annotations

from addt_dsl.runtime import oracles
from addt_dsl.runtime.bound import BoundScenario
from addt_dsl.runtime.result import Verdict
from addt_dsl.runtime.signals import compute_signals
from addt_dsl.runtime.trace import Trace


def judge(bound: BoundScenario, trace: Trace) -> list[Verdict]:
    """Evaluate every oracle of the bound scenario on a trace (robustness at time 0)."""
    out = []
    for o in bound.oracles:
        formula = oracles.prepare(o.formula)
        signals = compute_signals(trace, formula.signals)
        rho = float(oracles.robustness_at_0(formula, signals, trace.period_s))
        passed = oracles.satisfied(formula, signals, trace.period_s)
        first = None if passed else oracles.first_violation_time(formula, signals, trace.period_s)
        out.append(Verdict(o.name, o.severity, rho, passed, first))
    return out
