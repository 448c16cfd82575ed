"""The examples in docs/stack.md and docs/bridge.md run as written."""

import re
from pathlib import Path

import pytest

DOCS = Path(__file__).resolve().parents[3] / "docs"


def _blocks(name: str, lang: str) -> list[str]:
    return re.findall(rf"```{lang}\n(.*?)```", (DOCS / name).read_text(encoding="utf-8"), flags=re.S)


def test_bridge_md_minimal_remote_stack_runs():
    (block,) = _blocks("bridge.md", "python")
    exec(compile(block, str(DOCS / "bridge.md"), "exec"), {})


@pytest.mark.parametrize("block", _blocks("stack.md", "python"))
def test_stack_md_python_examples_run(block):
    exec(compile(block, str(DOCS / "stack.md"), "exec"), {})


def test_stack_md_scenario_compiles():
    from addt_dsl.compiler import compile_source
    from tests.conftest import compiled_as_installed

    blocks = _blocks("stack.md", "addt")
    assert blocks
    for text in blocks:
        result = compile_source(text)
        assert compiled_as_installed(result), result.diagnostics
