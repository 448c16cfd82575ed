"""Oracles: signal temporal logic with quantitative robustness (see docs/oracles.md).

The runtime evaluates formula trees (`addt_dsl.expr`); it never parses text. Formulas as
text are read by the compiler (`addt_dsl.compiler.formula.parse_formula`).
"""

from __future__ import annotations

from addt_dsl.runtime.oracles.stl import (
    Formula,
    FormulaTypeError,
    UnknownSignalError,
    UnsubstitutedParameterError,
    boolean_semantics,
    evaluate,
    first_violation_time,
    prepare,
    robustness_at_0,
    robustness_over_time,
    samples,
    satisfied,
    verdicts,
)

__all__ = [
    "Formula", "FormulaTypeError", "UnknownSignalError", "UnsubstitutedParameterError",
    "boolean_semantics", "evaluate", "first_violation_time", "prepare", "robustness_at_0", "robustness_over_time",
    "samples", "satisfied", "verdicts",
]
