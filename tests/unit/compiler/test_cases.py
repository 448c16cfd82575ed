"""Every file in cases/ produces exactly the diagnostics its `# expect:` comments state."""

from __future__ import annotations

import pytest
from tests.unit.compiler.conftest import CASES_DIR, describe, expectations, found

from addt_dsl.compiler import compile_file

CASES = sorted(CASES_DIR.glob("*.addt"))


@pytest.mark.parametrize("path", CASES, ids=[p.stem for p in CASES])
def test_case(path):
    result = compile_file(path)
    want = expectations(path.read_text())
    got = found(result)
    assert got == want, f"\nmissing: {sorted(want - got)}\nextra: {sorted(got - want)}\n{describe(result)}"
    if not want:
        assert result.ok, describe(result)
    elif any(code.startswith("E") for code, _, _ in want):
        assert not result.ok and result.plan is None


def test_there_are_cases():
    assert len(CASES) >= 10
