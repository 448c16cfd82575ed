"""Oracles: signal temporal logic with quantitative robustness (see docs/oracles.md)."""

from __future__ import annotations

from addt_dsl.runtime.oracles.formula_text import FormulaSyntaxError, format_formula, parse_formula
from addt_dsl.runtime.oracles.stl import (
    FormulaTypeError,
    UnknownSignalError,
    UnsubstitutedParameterError,
    boolean_semantics,
    evaluate,
    first_violation_time,
    robustness_at_0,
    robustness_over_time,
    samples,
    satisfied,
    verdicts,
)

__all__ = [
    "FormulaSyntaxError", "FormulaTypeError", "UnknownSignalError", "UnsubstitutedParameterError",
    "boolean_semantics", "evaluate", "first_violation_time", "format_formula", "parse_formula",
    "robustness", "robustness_at_0", "robustness_over_time", "samples", "satisfied", "verdicts",
]


def robustness(formula: str, signals: dict[str, list[float]], period_s: float) -> float:
    """Robustness at time 0 of a formula given as text, over signals sampled every
    `period_s` seconds (all the same length, sample 0 at time 0).

    Raises FormulaSyntaxError (a ValueError, with the column) for bad text and
    UnknownSignalError (a KeyError) naming a signal the formula uses but `signals` lacks.
    """
    # The evaluator converts only the signals the formula uses to arrays.
    return robustness_at_0(parse_formula(formula), signals, period_s)
