"""The README's scenario example compiles."""

import re

from addt_dsl.compiler import compile_source
from tests.conftest import ROOT, assert_scenarios_compile


def test_readme_examples_compile():
    text = (ROOT / "README.md").read_text()
    blocks = re.findall(r"```addt\n(.*?)```", text, re.S)
    assert blocks
    for block in blocks:
        result = compile_source(block, "README.md")
        assert result.ok, [str(d) for d in result.diagnostics]


def test_readme_suite_commands_name_files_that_compile():
    text = (ROOT / "README.md").read_text()
    commands = re.findall(r"^addtc (examples/\S+)", text, re.M)
    assert len(commands) >= 3
    assert_scenarios_compile(commands)
