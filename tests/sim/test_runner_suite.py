"""`addtc DIR|FILE... --by PARAM`: several files in one command, one combined table."""

import json
from xml.etree import ElementTree as ET

import pytest

from tests.sim.runner_simkit import addtc, limit_scenario

pytestmark = pytest.mark.slow


def test_a_directory_runs_each_file_and_tables_success_by_parameter(tmp_path):
    suite = tmp_path / "suite"
    suite.mkdir()
    limit_scenario(suite, repeat=2, duration="4 s").rename(suite / "a_limit.addt")
    (suite / "b_far.addt").write_text((suite / "a_limit.addt").read_text()
                                      .replace("scenario limit", "scenario far")
                                      .replace("grid limit in [70, 200] m", "grid limit in [190, 200] m"))
    out = tmp_path / "out"
    junit = tmp_path / "junit.xml"
    proc = addtc(suite, "--by", "limit", "--jobs", "2", "--out", out, "--no-report", "--junit", junit)
    assert proc.returncode == 1, proc.stderr  # the 70 m cell fails
    root = ET.parse(junit).getroot()  # one <testsuite> per file, totals over both
    assert [s.get("name") for s in root.findall("testsuite")] == ["limit", "far"]
    assert (root.get("tests"), root.get("failures")) == ("16", "4")
    assert "success rate by limit" in proc.stdout
    summary = json.loads((out / "suite.json").read_text())
    assert [f["scenario"] for f in summary["files"]] == ["limit", "far"]
    limit, far = summary["files"]
    assert {c["label"]: (c["runs"], c["passed"]) for c in limit["by"]} == {"70 m": (4, 0), "200 m": (4, 4)}
    assert {c["label"]: (c["runs"], c["passed"]) for c in far["by"]} == {"190 m": (4, 4), "200 m": (4, 4)}
    assert (limit["exit_code"], far["exit_code"], summary["runs"], summary["passed"]) == (1, 0, 16, 12)
    for name in ("a_limit", "b_far"):  # each file keeps its own results directory
        assert (out / name / "runs.csv").exists() and (out / name / "results.sqlite").exists()


def test_suite_errors_are_usage_errors(tmp_path):
    empty = tmp_path / "empty"
    empty.mkdir()
    proc = addtc(empty)
    assert proc.returncode == 2 and "no .addt files" in proc.stderr
    one = limit_scenario(tmp_path, repeat=1, duration="1 s")
    other = tmp_path / "other.addt"
    other.write_text(one.read_text())
    proc = addtc(one, other, "--store", tmp_path / "x.sqlite")
    assert proc.returncode == 2 and "--store" in proc.stderr


def test_a_classified_suite_counts_outcomes_per_file_and_value(tmp_path):
    one = limit_scenario(tmp_path, repeat=1, duration="2 s", limits="200")
    other = tmp_path / "other.addt"
    other.write_text(one.read_text().replace("scenario limit", "scenario other"))
    out = tmp_path / "out"
    proc = addtc(one, other, "--by", "drop", "--classify", "--jobs", "2", "--out", out, "--no-report")
    assert proc.returncode == 0, proc.stderr
    assert "masked/silent/detected/hazard" in proc.stdout
    summary = json.loads((out / "suite.json").read_text())
    for f in summary["files"]:
        assert sum(f["outcomes"].values()) == f["runs"] == 2
        by = {c["value"]: c for c in f["by"]}
        assert by[0.0]["outcomes"] == {"masked": 1}  # no drops: the run is its own twin


def test_addtc_study_runs_the_fault_studies(tmp_path):
    one = limit_scenario(tmp_path, repeat=1, duration="4 s")  # the 70 m cell fails near 2.5 s
    out = tmp_path / "out"
    assert addtc(one, "--jobs", "1", "--out", out, "--no-report").returncode == 1
    table = addtc("study", "table", out / "runs.csv", "--by", "limit")
    assert table.returncode == 0, table.stderr
    assert "success_rate" in table.stdout and "70" in table.stdout
    perception = addtc("study", "perception", one, "--limit", "1")
    assert perception.returncode == 0, perception.stderr
    assert "position_error_m" in perception.stdout
    assert "usage: addtc study" in addtc("study", "--help").stdout
