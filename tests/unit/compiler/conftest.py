"""Shared helpers for compiler tests: inline expectations in .addt sources.

A source states the diagnostics it must produce with comments:

    # expect: E0201 @ 12:5      an error or warning with this code at line 12, column 5
    # expect: ok                compiles with no diagnostics at all (the default)

The test compares the set of (code, line, col) of every diagnostic with the set expected,
so a missing, extra or misplaced diagnostic fails.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

from hypothesis import HealthCheck, settings

REPO = Path(__file__).resolve().parents[3]
CASES_DIR = Path(__file__).resolve().parent / "cases"
EXPECT_RE = re.compile(r"#\s*expect:\s*([EW]\d{4})\s*@\s*(\d+):(\d+)")

# Fuzz budget: `ci` by default (a few seconds); ADDT_FUZZ_EXAMPLES=20000 for a long hunt.
FUZZ = settings(max_examples=int(os.environ.get("ADDT_FUZZ_EXAMPLES", "150")), deadline=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                       HealthCheck.filter_too_much])


def expectations(text: str) -> set[tuple[str, int, int]]:
    return {(m.group(1), int(m.group(2)), int(m.group(3))) for m in EXPECT_RE.finditer(text)}


def found(result) -> set[tuple[str, int, int]]:
    return {(d.code, d.span.line if d.span else 0, d.span.col if d.span else 0) for d in result.diagnostics}


def describe(result) -> str:
    from addt_dsl.diagnostics import render_text

    return render_text(result.diagnostics, result.sources)
