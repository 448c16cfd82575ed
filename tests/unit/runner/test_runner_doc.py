"""The Python example of docs/running.md runs as written, and the options it lists are
the CLI's."""

import re
from pathlib import Path

from addt_dsl.cli import build_parser

DOC = Path(__file__).resolve().parents[3] / "docs" / "running.md"


def test_python_example(tmp_path, monkeypatch):
    blocks = re.findall(r"```python\n(.*?)```", DOC.read_text(), re.S)
    assert blocks
    monkeypatch.chdir(tmp_path)
    for block in blocks:
        exec(compile(block, str(DOC), "exec"), {"__name__": "doc_example"})
    assert (tmp_path / "runs.parquet").exists() and (tmp_path / "runs.csv").exists()


def test_every_run_option_is_documented():
    run = next(a for a in build_parser()._subparsers._group_actions[0].choices.values() if a.prog.endswith("run"))
    options = {o for action in run._actions for o in action.option_strings if o.startswith("--") and o != "--help"}
    documented = set(re.findall(r"\| `(--[a-z-]+)", DOC.read_text()))
    assert options == documented
