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


def assert_scenarios_compile(patterns) -> None:
    """Every glob pattern (relative to the repository) names files, and each compiles:
    docs that give commands over examples must not point at missing or broken files."""
    from addt_dsl.compiler import compile_file

    for pattern in patterns:
        paths = sorted(ROOT.glob(pattern))
        assert paths, pattern
        for path in paths:
            result = compile_file(path)
            assert result.ok, (path, [str(d) for d in result.diagnostics])
