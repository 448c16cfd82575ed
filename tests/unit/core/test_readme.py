"""The README's suite commands name files that compile (tests/docs_harness.py compiles and
runs its scenario example)."""

import re

from tests.conftest import ROOT, assert_scenarios_compile


def test_readme_suite_commands_name_files_that_compile():
    text = (ROOT / "README.md").read_text()
    commands = re.findall(r"^addtc (examples/\S+)", text, re.M)
    assert len(commands) >= 3
    assert_scenarios_compile(commands)
