"""The README's suite commands name files that compile (tests/docs_harness.py compiles and
runs its scenario example)."""

import re

from tests.conftest import ROOT, assert_scenarios_compile


def test_readme_suite_commands_name_files_that_compile():
    text = (ROOT / "README.md").read_text()
    commands = re.findall(r"^addtc (examples/\S+)", text, re.M)
    assert len(commands) >= 3
    assert_scenarios_compile(commands)


def test_readme_scenario_is_the_shipped_example():
    """The README's scenario is `examples/overtake.addt` byte for byte, so the table a new
    user gets from `addtc examples/overtake.addt` has the columns the README shows."""
    text = (ROOT / "README.md").read_text()
    block = re.search(r"```addt[^\n]*\n(.*?)```", text, re.S).group(1)
    assert block == (ROOT / "examples" / "overtake.addt").read_text()


def test_readme_command_table_lists_every_subcommand():
    from addt_dsl.cli import build_parser

    text = (ROOT / "README.md").read_text()
    table = [line for line in text.splitlines() if line.startswith("| `addtc ")]
    listed = {line.split("`")[1].split()[1] for line in table}
    sub = build_parser()._subparsers._group_actions[0].choices
    assert set(sub) - {"run"} <= listed | {"DIR|FILE..."}, set(sub) - listed
