"""Oracles: signal temporal logic with quantitative robustness (see docs/oracles.md)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from addt_dsl.runtime.oracles.formula_text import FormulaSyntaxError, format_formula, parse_formula
from addt_dsl.runtime.oracles.stl import (
    FormulaTypeError,
    UnknownSignalError,
    UnsubstitutedParameterError,
    boolean_semantics,
    evaluate,
    first_violation_time,
    robustness_at_0,
    samples,
    satisfied,
    verdicts,
)

__all__ = [
    "FormulaSyntaxError", "FormulaTypeError", "UnknownSignalError", "UnsubstitutedParameterError",
    "boolean_semantics", "evaluate", "first_violation_time", "format_formula", "parse_formula",
    "robustness", "robustness_at_0", "samples", "satisfied", "verdicts",
]


def robustness(formula: str, signals: dict[str, list[float]], period_s: float) -> float:
    """Robustness at time 0 of a formula given as text, over signals sampled every
    `period_s` seconds (all the same length, sample 0 at time 0).

    Raises FormulaSyntaxError (a ValueError, with the column) for bad text and
    UnknownSignalError (a KeyError) naming a signal the formula uses but `signals` lacks.
    """
    expr = parse_formula(formula)
    arrays: Mapping[str, np.ndarray] = {k: _array(k, v) for k, v in signals.items()}
    return robustness_at_0(expr, arrays, period_s)


def _array(name: str, values: Sequence[float]) -> np.ndarray:
    return np.asarray(values, dtype=np.float64)
