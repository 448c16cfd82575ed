"""The README's scenario example compiles."""

import re

from addt_dsl.compiler import compile_source
from tests.conftest import ROOT


def test_readme_examples_compile():
    text = (ROOT / "README.md").read_text()
    blocks = re.findall(r"```addt\n(.*?)```", text, re.S)
    assert blocks
    for block in blocks:
        result = compile_source(block, "README.md")
        assert result.ok, [str(d) for d in result.diagnostics]
