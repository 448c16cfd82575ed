"""The options docs/running.md lists are the CLI's (tests/docs_harness.py runs its examples)."""

import re
from pathlib import Path

from addt_dsl.cli import build_parser

DOC = Path(__file__).resolve().parents[3] / "docs" / "running.md"


def test_every_run_option_is_documented():
    run = next(a for a in build_parser()._subparsers._group_actions[0].choices.values() if a.prog.endswith("run"))
    options = {o for action in run._actions for o in action.option_strings if o.startswith("--") and o != "--help"}
    documented = set(re.findall(r"\| `(--[a-z-]+)", DOC.read_text()))
    assert options == documented
