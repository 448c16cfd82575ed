"""Shared fixtures: paths and compiled examples."""

from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "examples"


@pytest.fixture(scope="session")
def overtake_plan():
    from addt_dsl.compiler import compile_file

    result = compile_file(EXAMPLES / "overtake.addt")
    assert result.ok, result.diagnostics
    return result.plan
