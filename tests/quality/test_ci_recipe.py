"""docs/ci.md's recipe for a repository that is not this one, run as written in a scratch git
repository: maps beside the scenarios (read through the rootdir and `--root`), the `ci`
extra's pytest and the plugin, a passing gate."""

from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from docs.regen import doc_blocks

ROOT = Path(__file__).resolve().parents[2]

SCENARIO = """scenario follow {
  duration 3 s
  step 50 ms
  road main import "../maps/town.xodr"
  ego car on main lane -1 at 20 m speed 12 m/s {
    stack bev cruise_speed 12 m/s
  }
  agent lead car on main lane -1 at 60 m speed 12 m/s
  expect {
    no collision
  }
}
"""

pytestmark = pytest.mark.slow


def _recipe() -> list[str]:
    (block,) = [b for b in doc_blocks(ROOT / "docs" / "ci.md") if "recipe" in b.attrs]
    return [line for line in block.text.splitlines() if line.strip()]


def test_the_ci_extra_is_pytest_only():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert project["optional-dependencies"]["ci"] == ["pytest>=8"]
    # What the plugin imports beyond pytest is a core dependency.
    core = {re.split(r"[<>=!\[ ]", d)[0] for d in project["dependencies"]}
    assert "hypothesis" in core
    plugin = (ROOT / "addt_dsl" / "pytest_plugin.py").read_text()
    third_party = set(re.findall(r"^\s*(?:from|import) (\w+)", plugin, re.M)) - {"addt_dsl", "__future__", "os",
                                                                                 "fnmatch", "pathlib", "warnings"}
    assert third_party <= {"pytest", "hypothesis"}, third_party


def test_the_recipe_runs_in_another_repository(tmp_path):
    repo = tmp_path / "your-repo"
    (repo / "scenarios").mkdir(parents=True)
    (repo / "maps").mkdir()
    shutil.copy(ROOT / "examples" / "maps" / "straight_500m.xodr", repo / "maps" / "town.xodr")
    (repo / "scenarios" / "follow.addt").write_text(SCENARIO)
    (repo / "pytest.ini").write_text("[pytest]\n")
    if shutil.which("git"):
        subprocess.run(["git", "init", "-q", str(repo)], check=True)
    env = {k: v for k, v in os.environ.items() if k not in ("CI", "GITHUB_ACTIONS")}
    env["PYTHONPATH"] = str(ROOT)  # the installed package, as `pip install addt-dsl[ci]` gives it
    programs = {"addtc": [sys.executable, "-m", "addt_dsl.cli"], "pytest": [sys.executable, "-m", "pytest"]}
    ran = []
    for line in _recipe():
        argv = shlex.split(line.split("  #")[0])
        if argv[:2] == ["pip", "install"]:
            assert argv[2] == "addt-dsl[ci]"
            continue
        expanded = []
        for a in argv[1:]:  # the shell's globbing
            expanded += sorted(str(p.relative_to(repo)) for p in repo.glob(a)) if "*" in a else [a]
        proc = subprocess.run(programs[argv[0]] + expanded, cwd=repo, env=env, capture_output=True, text=True,
                              timeout=300)
        assert proc.returncode == 0, (line, proc.stdout[-3000:], proc.stderr[-3000:])
        ran.append((argv[0], proc.stdout))
    assert [p for p, _ in ran] == ["addtc", "pytest", "addtc"]
    assert "1 passed" in ran[1][1]
    assert (repo / "results" / "report.html").is_file() and (repo / "results" / "junit.xml").is_file()
    assert (repo / "scenario-report.xml").is_file()
    # Without --root the map beside the scenarios is refused, and says how to allow it.
    refused = subprocess.run(programs["addtc"] + ["check", "scenarios/follow.addt"], cwd=repo, env=env,
                             capture_output=True, text=True)
    assert refused.returncode == 2 and "E0402" in refused.stderr and "--root" in refused.stderr
