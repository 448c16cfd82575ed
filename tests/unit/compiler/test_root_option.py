"""`--root DIR`: includes and maps from anywhere under DIR (a repository's maps/ beside its
scenarios/), still nothing outside it; DIR must hold the scenario."""

from __future__ import annotations

import shutil

from addt_dsl.compiler import compile_file
from tests.conftest import ROOT

SCENARIO = """scenario follow {
  duration 3 s
  road main import "../maps/town.xodr"
  ego car on main lane -1 at 20 m speed 12 m/s
}
"""


def _repo(tmp_path):
    (tmp_path / "repo" / "scenarios").mkdir(parents=True)
    (tmp_path / "repo" / "maps").mkdir()
    shutil.copy(ROOT / "examples" / "maps" / "straight_500m.xodr", tmp_path / "repo" / "maps" / "town.xodr")
    path = tmp_path / "repo" / "scenarios" / "follow.addt"
    path.write_text(SCENARIO)
    return tmp_path / "repo", path


def _errors(result):
    return [d.code for d in result.diagnostics if d.is_error]


def test_root_widens_what_may_be_read(tmp_path):
    repo, path = _repo(tmp_path)
    assert _errors(compile_file(path)) == ["E0402"]
    assert compile_file(path, root=repo).ok


def test_nothing_outside_the_root_and_the_root_holds_the_scenario(tmp_path):
    repo, path = _repo(tmp_path)
    path.write_text(SCENARIO.replace("../maps/town.xodr", "../../outside.xodr"))
    shutil.copy(repo / "maps" / "town.xodr", tmp_path / "outside.xodr")
    assert _errors(compile_file(path, root=repo)) == ["E0402"]
    assert _errors(compile_file(path, root=repo / "maps")) == ["E0402"]  # does not hold the scenario
