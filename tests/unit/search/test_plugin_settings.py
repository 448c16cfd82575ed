"""How the pytest plugin sizes its search from Hypothesis profiles, and how it reads its
failure corpus."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from addt_dsl.pytest_plugin import SEARCH_RUNS, search_runs_for

ROOT = Path(__file__).resolve().parents[3]


def test_profile_table():
    assert search_runs_for("default", 100, []) == 0
    assert search_runs_for("ci", 100, []) == SEARCH_RUNS["ci"] == 10
    assert search_runs_for("nightly", 1000, []) == 300
    assert search_runs_for("mine", 42, []) == 42  # unlisted profiles use max_examples


def test_ini_overrides():
    assert search_runs_for("ci", 100, ["ci=25", "nightly=5000"]) == 25
    assert search_runs_for("default", 100, ["default=3"]) == 3
    assert search_runs_for("ci", 100, ["ci=lots"]) == 10  # not a number: ignored


def test_nightly_profile_is_registered():
    from hypothesis import settings

    assert settings.get_profile("nightly").max_examples >= 300


SCENARIO = """scenario t {
  duration 1 s
  road r {
    line length 200 m
  }
  ego car on r lane -1 at 20 m speed 10 m/s
}
"""


@pytest.mark.parametrize("entry", [b"# source: t.addt\nscenario t {\n  garbage\n",
                                   b"# source: t.addt\n\xff\xfe scenario t {\n"])
def test_a_damaged_corpus_entry_fails_its_test_without_a_traceback(entry, tmp_path):
    """A corpus entry that no longer compiles (edited, damaged, older than the language)
    failed the test with the plugin's traceback (ValueError from compile_pinned; an
    entry that is not UTF-8, UnicodeDecodeError): now the entry's diagnostics and what to do."""
    (tmp_path / "t.addt").write_text(SCENARIO)
    (tmp_path / "pytest.ini").write_text("[pytest]\n")
    (tmp_path / ".addt-failures").mkdir()
    (tmp_path / ".addt-failures" / "t-bad.addt").write_bytes(entry)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run([sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "t.addt"], cwd=tmp_path,
                          env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 1, done.stdout + done.stderr
    assert "corpus entry .addt-failures/t-bad.addt cannot be replayed" in done.stdout
    assert "fix it, or delete it if it is stale" in done.stdout
    assert "Traceback" not in done.stdout and "pytest_plugin.py" not in done.stdout, done.stdout
