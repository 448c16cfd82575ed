"""The pytest plugin end to end, in a scratch project run by a child pytest."""

from __future__ import annotations

import os
import subprocess
import sys
from importlib.metadata import entry_points
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
TEN_FAULTS = (ROOT / "examples" / "ten_faults.addt").read_text()

PASSING = """scenario follow {
  duration 3 s
  step 20 ms
  road street {
    line length 300 m
  }
  param lead_gap = 35 m in [30 m, 40 m]
  ego car on street lane -1 at 10 m speed 14 m/s {
    stack bev cruise_speed 15 m/s
  }
  agent lead car on street lane -1 at 10 m + lead_gap speed 14 m/s {
    behavior cruise speed 14 m/s
  }
  expect {
    no collision
  }
  sweep {
    grid lead_gap in [32, 38] m
  }
}
"""

pytestmark = pytest.mark.slow


CI_VARS = ("CI", "GITHUB_ACTIONS", "GITLAB_CI", "BUILD_ID", "TF_BUILD", "CIRCLECI", "JENKINS_URL")


# With the package installed the entry point loads the plugin; `-p` again would register it twice.
PLUGIN_ARGS = ([] if any(ep.name == "addt" for ep in entry_points(group="pytest11"))
               else ["-p", "addt_dsl.pytest_plugin"])


def _pytest(project: Path, *args: str, github: bool = False) -> subprocess.CompletedProcess:
    plugin = PLUGIN_ARGS
    # Hypothesis loads its `ci` profile by itself on a CI machine: start from a clean slate.
    env = {k: v for k, v in os.environ.items() if k not in CI_VARS}
    env["PYTHONPATH"] = str(ROOT)
    if github:
        env["GITHUB_ACTIONS"] = "true"
    return subprocess.run([sys.executable, "-m", "pytest", *plugin, "-p", "no:cacheprovider", *args],
                          cwd=project, env=env, capture_output=True, text=True, timeout=600)


@pytest.fixture
def project(tmp_path: Path) -> Path:
    (tmp_path / "pytest.ini").write_text("[pytest]\n")
    (tmp_path / "scenarios").mkdir()
    (tmp_path / "scenarios" / "follow.addt").write_text(PASSING)
    (tmp_path / "scenarios" / "shared.addt").write_text("param unused = 1 m\n")  # definitions only
    return tmp_path


def test_collects_scenarios_one_per_file_or_per_cell(project):
    out = _pytest(project, "--collect-only", "-q", "scenarios")
    assert "scenarios/follow.addt::follow" in out.stdout
    assert "shared.addt" not in out.stdout
    cells = _pytest(project, "--collect-only", "-q", "--addt-per-cell", "scenarios")
    assert "follow.addt::follow[lead_gap=32m]" in cells.stdout
    assert "follow.addt::follow[lead_gap=38m]" in cells.stdout


def test_profiles_size_the_search(project):
    ci = _pytest(project, "-rP", "--hypothesis-profile", "ci", "scenarios")
    assert ci.returncode == 0, ci.stdout + ci.stderr
    assert "sweep: 2 run(s), 0 failing" in ci.stdout
    assert "search (cem): 10 run(s), no failure" in ci.stdout
    nightly = _pytest(project, "-rP", "--hypothesis-profile", "nightly", "-o", "addt_search_runs=nightly=40",
                      "scenarios")
    assert nightly.returncode == 0
    assert "search (cem): 40 run(s), no failure" in nightly.stdout
    default = _pytest(project, "-rP", "scenarios")
    assert default.returncode == 0
    assert "search" not in default.stdout.split("addt", 1)[-1]


def test_project_suite_does_not_collect_examples():
    out = subprocess.run([sys.executable, "-m", "pytest", "--collect-only", "-q", *PLUGIN_ARGS,
                          "tests/unit/search"], cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)},
                         capture_output=True, text=True)
    assert ".addt" not in out.stdout
    assert "test_falsify.py" in out.stdout


def test_violated_warn_oracle_is_a_warning_not_a_failure(project):
    (project / "scenarios" / "follow.addt").write_text(
        PASSING.replace("no collision", "no collision\n    warn crawl: always ego.speed < 5 m/s"))
    junit = project / "report.xml"
    out = _pytest(project, f"--junitxml={junit}", "scenarios")
    assert out.returncode == 0, out.stdout + out.stderr
    assert "AddtWarning: scenarios/follow.addt: warning: crawl violated in 2 of 2 run(s)" in out.stdout
    assert '<property name="warning.crawl" value="2"' in junit.read_text()
    strict = _pytest(project, "-W", "error::addt_dsl.pytest_plugin.AddtWarning", "scenarios")
    assert strict.returncode == 1


def _plugin_output(project: Path, batch: int) -> dict:
    """A child pytest on ten_faults at `--addt-batch N` (CI profile, GitHub annotations, a
    JUnit report) in a fresh `project`, then again with its corpus: the reports (timings and
    the project's path out), the JUnit XML and the corpus entry it wrote."""
    import re

    (project / "scenarios").mkdir(parents=True)
    (project / "pytest.ini").write_text("[pytest]\n")
    (project / "scenarios" / "ten_faults.addt").write_text(TEN_FAULTS)

    def report(proc):
        # Timings out, and the '=' padding pytest sizes around them ("in 9.9s" and "in 10.1s"
        # pad the summary line differently); each batch size has its own project directory.
        text = proc.stdout.replace(str(project), "<project>")
        return re.sub(r"={2,}", "==", re.sub(r" in [0-9.]+s", "", text))

    junit = project / "report.xml"
    first = _pytest(project, "--hypothesis-profile", "ci", "-rA", "--addt-batch", str(batch),
                    f"--junitxml={junit}", "scenarios/ten_faults.addt", github=True)
    assert first.returncode == 1, first.stdout + first.stderr
    corpus = sorted((project / ".addt-failures").glob("ten_faults-*.addt"))
    assert len(corpus) == 1, corpus
    entry = corpus[0]
    again = _pytest(project, "--hypothesis-profile", "ci", "-rA", "--addt-batch", str(batch),
                    "scenarios/ten_faults.addt")
    return {"first": report(first), "junit": junit.read_text(), "entry": entry.read_text(),
            "again": report(again), "again_rc": again.returncode, "entry_path": entry, "project": project}


@pytest.fixture(scope="module")
def ten_faults_plugin(tmp_path_factory) -> dict:
    """`_plugin_output` at `--addt-batch` 1 and 8: batch -> outputs. Both tests below read
    them; each ran its own child pytests on ten_faults before (six in all, now four). The two
    batch sizes run at once, each in its own project (a child pytest uses one core:
    `--addt-jobs` 1)."""
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(max_workers=2) as pool:
        futures = {batch: pool.submit(_plugin_output, tmp_path_factory.mktemp(f"batch{batch}") / "project", batch)
                   for batch in (1, 8)}
        return {batch: future.result() for batch, future in futures.items()}


def test_failure_is_shrunk_reported_and_replayed_first(ten_faults_plugin):
    """One run at a time (`--addt-batch 1`; the shrink's default)."""
    out = ten_faults_plugin[1]
    project = out["project"]
    first, xml, entry = out["first"], out["junit"], out["entry_path"]
    shown = entry.relative_to(project)
    assert f"no_collision fails: minimal counterexample {shown}" in first
    assert "did not matter: fault drop lidar from 0 s (scenarios/ten_faults.addt:29)" in first
    assert "::error file=scenarios/ten_faults.addt,title=addt: no_collision fails::" in first
    assert "<failure message=\"no_collision fails: minimal counterexample" in xml
    assert 'name="counterexample"' in xml
    # The counterexample replays with addtc: exit 1.
    replay = subprocess.run([sys.executable, "-m", "addt_dsl.cli", str(entry), "--jobs", "1"],
                            env={**os.environ, "PYTHONPATH": str(ROOT)}, capture_output=True, text=True)
    assert replay.returncode == 1
    # Next time the known counterexample is replayed first and fails the test by itself.
    assert out["again_rc"] == 1
    assert f"known counterexample {shown} still fails" in out["again"]


def test_batched_runs_give_the_same_test_reports_and_counterexamples(ten_faults_plugin):
    """`--addt-batch`: the sweep, the corpus and the shrink step runs together; the reports,
    the corpus entry and the replay are those of one run at a time."""
    keys = ("first", "entry", "again", "again_rc")
    assert {k: ten_faults_plugin[8][k] for k in keys} == {k: ten_faults_plugin[1][k] for k in keys}
    out = ten_faults_plugin[1]
    assert "no_collision fails: minimal counterexample" in out["first"] and "stuck control.accel" in out["entry"]
    assert "still fails" in out["again"]
