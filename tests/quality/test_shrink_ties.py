"""A failure in a scenario with `reach goal within T` is shrunk, reported and written as a
counterexample that compiles, by `addtc shrink`, `addtc falsify` and the pytest plugin
(the shrinker cut the run below T: exit 3 and a broken `.addt-failures/` entry); a corpus
entry is tied to the content of its scenario (an edited scenario replayed a stale one)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from tests.quality.test_shrink_pytest_plugin import _pytest

from addt_dsl.cli import main as addtc
from addt_dsl.compiler import compile_file

ROOT = Path(__file__).resolve().parents[2]

# The ego is pushed into a stopped car at 2.5 s; `reach goal within 10 s` ties the run's end.
WITHIN = """scenario within {
  duration 12 s
  step 50 ms
  road street {
    line length 400 m
  }
  param gap = 40 m in [30 m, 60 m]
  ego car on street lane -1 at 10 m speed 14 m/s goal 150 m {
    stack bev cruise_speed 15 m/s
  }
  agent lead car on street lane -1 at 10 m + gap speed 0 m/s
  faults {
    from 1 s stuck control.accel value 3
  }
  expect {
    no collision
    reach goal within 10 s
  }
}
"""

pytestmark = pytest.mark.slow


def _compiles(path: Path) -> None:
    result = compile_file(path)
    assert result.ok, result.diagnostics
    assert result.plan.duration_s >= 10.0


def test_shrink_and_falsify_write_counterexamples_that_compile(tmp_path, capsys):
    scenario = tmp_path / "within.addt"
    scenario.write_text(WITHIN)
    assert addtc(["shrink", str(scenario), "--out", str(tmp_path / "min"), "--no-animation",
                  "--max-simulations", "40"]) == 1
    (written,) = (tmp_path / "min").glob("*.addt")
    _compiles(written)
    assert "internal error" not in capsys.readouterr().err
    code = addtc(["falsify", str(scenario), "--out", str(tmp_path / "fal"), "--budget-runs", "4",
                  "--shrink-simulations", "20", "--sampler", "random", "--jobs", "1"])
    assert code == 1
    found = list((tmp_path / "fal").glob("*.addt"))
    assert found
    for path in found:
        _compiles(path)


def test_pytest_plugin_keeps_a_corpus_entry_that_compiles(tmp_path):
    (tmp_path / "pytest.ini").write_text("[pytest]\n")
    (tmp_path / "within.addt").write_text(WITHIN)
    out = _pytest(tmp_path, "--addt-shrink-simulations", "30", "within.addt")
    assert out.returncode == 1, out.stdout + out.stderr
    assert "Traceback" not in out.stdout and "minimal counterexample" in out.stdout
    (entry,) = (tmp_path / ".addt-failures").glob("*.addt")
    _compiles(entry)
    replay = subprocess.run([sys.executable, "-m", "addt_dsl.cli", str(entry), "--jobs", "1", "--no-report"],
                            env={**os.environ, "PYTHONPATH": str(ROOT)}, capture_output=True, text=True)
    assert replay.returncode == 1, replay.stderr
    # Unchanged but for a comment, the scenario replays its entry first: it fails again.
    (tmp_path / "within.addt").write_text("# a comment\n" + WITHIN)
    again = _pytest(tmp_path, "-rA", "within.addt")
    assert again.returncode == 1 and "still fails" in again.stdout, again.stdout
    # Fixed (the fault gone, the lead moving), the entry of the old content is not replayed.
    fixed = WITHIN.replace("  faults {\n    from 1 s stuck control.accel value 3\n  }\n", "")
    (tmp_path / "within.addt").write_text(fixed.replace("speed 0 m/s", "speed 14 m/s"))
    after = _pytest(tmp_path, "-rA", "within.addt")
    assert after.returncode == 0, after.stdout
    assert f"skipped .addt-failures/{entry.name}: written for an earlier version of within.addt" in after.stdout
