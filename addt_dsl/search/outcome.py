"""How the search judges a run: the failure modes of its violated oracles.

A failure's identity is its oracle plus its *mode*, the analogue of Hypothesis's
`interesting_origin` (exception type and location): the atomic comparison of the
oracle's formula that was worst at the first violation time, refined by what the
trace says about it (`MODE_REFINERS`: whom the ego hit, which side it left its lane
on). Shrinking keeps the identity, so a collision with the lead never "shrinks" into a
collision with the truck, nor a departure to the left into one to the right.
A run the stack aborts (exception, non-finite command) fails `stack_health` with the
error type as its mode (`RunResult.failures`).
"""

from __future__ import annotations

import math
import time
import traceback

import numpy as np

from addt_dsl import expr as E
from addt_dsl.plan import RunSpec
from addt_dsl.printer import PrinterError, format_expr
from addt_dsl.runtime import oracles
from addt_dsl.runtime.bound import BoundScenario, bind
from addt_dsl.runtime.execute import execute, execute_batch
from addt_dsl.runtime.result import RunResult
from addt_dsl.runtime.signals import compute_signals


def annotate_modes(spec: RunSpec, result: RunResult) -> None:
    """Name the mode of each violated hard oracle (needs the result's trace)."""
    failed = result.failed_verdicts
    bound = bind(spec) if failed else None
    for v in failed:
        v.mode = failure_mode(bound, result.trace, v.name, v.first_violation_s)


def evaluate(spec: RunSpec, keep_trace: bool = False) -> RunResult:
    """Run `spec` and judge it for the search; the trace is kept with `keep_trace`."""
    wall0 = time.perf_counter()
    try:
        result = execute(spec, keep_trace=True)
    except Exception as exc:  # noqa: BLE001 - a crashing run is a finding, not a search error
        return RunResult.unfinished(spec, "crashed", f"{type(exc).__name__}: {exc}\n{traceback.format_exc(limit=3)}",
                                    time.perf_counter() - wall0)
    annotate_modes(spec, result)
    if not keep_trace:
        result.trace = None
    return result


def evaluate_batch(specs: list[RunSpec], keep_trace: bool = False) -> list[RunResult]:
    """`evaluate` over runs stepped together (`execute_batch`): the same results as one by
    one (a run's trace does not depend on its batch). A batch whose set-up fails (one run's
    world or stack cannot be built) is judged run by run, so only that run is `crashed`."""
    if len(specs) == 1:
        return [evaluate(specs[0], keep_trace)]
    try:
        results = execute_batch(specs, keep_trace=True)
    except Exception:  # noqa: BLE001 - isolate the run that failed: each alone
        return [evaluate(spec, keep_trace) for spec in specs]
    for spec, result in zip(specs, results):
        annotate_modes(spec, result)
        if not keep_trace:
            result.trace = None
    return results


# An evaluator that can judge a batch names its batched form (`search.cache.Judge` uses it).
evaluate.batched = evaluate_batch


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


def failure_mode(bound: BoundScenario, trace, oracle_name: str, time_s: float | None) -> str:
    """The culprit comparison of a failed oracle at its first violation, refined."""
    formula = next(o.formula for o in bound.oracles if o.name == oracle_name)
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
    text = _atom_text(worst)
    notes = []
    for name in sorted(E.signals_used(worst)):
        fn, args = _signal_args(name)
        refine = MODE_REFINERS.get(fn)
        if refine is not None:
            note = refine(trace, args, k)
            if note:
                notes.append(note)
    return text + (f" [{', '.join(notes)}]" if notes else "")


def _atom_text(atom) -> str:
    try:
        return format_expr(atom)
    except PrinterError:
        return repr(atom)
