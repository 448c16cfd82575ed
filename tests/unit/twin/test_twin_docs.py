"""The .addt examples in docs/twin.md compile as written (tests/sim runs them)."""

import re
from pathlib import Path

import pytest

from addt_dsl.compiler import compile_source

ROOT = Path(__file__).resolve().parents[3]
DOC = ROOT / "docs" / "twin.md"
BLOCKS = re.findall(r"```addt\n(.*?)```", DOC.read_text(encoding="utf-8"), flags=re.S)


def test_doc_has_examples():
    assert len(BLOCKS) >= 3


@pytest.mark.parametrize("source", BLOCKS, ids=[re.search(r"scenario (\w+)", b).group(1) for b in BLOCKS])
def test_twin_doc_example_compiles(source):
    result = compile_source(source, path="docs/twin.md", base_dir=ROOT / "tests" / "data" / "xodr")
    assert result.plan is not None, [str(d) for d in result.diagnostics]
    assert not result.diagnostics
