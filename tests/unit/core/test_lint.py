"""Pyflakes' rules (ruff `F`) over the package, tests, benchmarks and docs scripts:
unused imports and variables, undefined names, f-strings without fields; and lines of at
most 120 characters (E501; pyproject's `[tool.ruff]`), with no file exempt. An unused import
of `runtime/` or `stack/` also changes the code fingerprint (run keys) for nothing."""

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import ROOT


def test_pyflakes_rules_pass():
    # The venv's own ruff, also when pytest runs as venv/bin/python without activating it.
    ruff = shutil.which("ruff", path=str(Path(sys.executable).parent)) or shutil.which("ruff")
    if ruff is None:
        pytest.skip("ruff is not installed (it comes with the `test` extra)")
    done = subprocess.run([ruff, "check", "--no-cache", "--select", "F,E501", "--output-format", "concise",
                           "addt_dsl", "tests", "benchmarks", "docs"], cwd=ROOT, capture_output=True, text=True,
                          check=False)
    assert done.returncode == 0, done.stdout + done.stderr


def test_no_file_is_exempt_from_the_line_length():
    import tomllib

    ruff = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["ruff"]
    exempt = {f for f, rules in ruff.get("lint", {}).get("per-file-ignores", {}).items() if "E501" in rules}
    assert exempt == set()
