"""The `addtc FILE` contract: exit codes, stores bound to one plan, per-run timeouts."""

import json
from xml.etree import ElementTree as ET

import pytest

from tests.sim.runner_simkit import addtc, limit_scenario

pytestmark = pytest.mark.slow


def test_exit_codes_and_json_summary(tmp_path):
    passing = limit_scenario(tmp_path, repeat=1, duration="2 s", limits="200")
    proc = addtc(passing, "--jobs", "2", "--format", "json")
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    assert (summary["runs"], summary["passed"], summary["failed"]) == (2, 2, 0)

    broken = tmp_path / "broken.addt"
    broken.write_text(passing.read_text().replace("duration 2 s", "duration 2 parsecs"))
    assert addtc(broken).returncode == 2


def test_a_store_of_another_plan_is_refused_unless_fresh(tmp_path):
    store = tmp_path / "r.sqlite"
    first = limit_scenario(tmp_path, repeat=1, duration="1 s", limits="200")
    assert addtc(first, "--jobs", "1", "--store", store, "--no-report").returncode == 0
    other = tmp_path / "other.addt"
    other.write_text(first.read_text().replace("duration 1 s", "duration 2 s"))
    refused = addtc(other, "--jobs", "1", "--store", store)
    assert refused.returncode == 2 and "another plan" in refused.stderr
    assert addtc(other, "--jobs", "1", "--store", store, "--fresh").returncode == 0


def test_runs_past_the_timeout_are_recorded_and_reported(tmp_path):
    slow = limit_scenario(tmp_path, repeat=1, duration="240 s", limits="200")  # seconds of wall time each
    junit = tmp_path / "junit.xml"
    proc = addtc(slow, "--jobs", "2", "--timeout", "0.3", "--junit", junit, "--format", "json")
    assert proc.returncode == 3  # the tool could not complete the runs: not "a run failed" (1)
    summary = json.loads(proc.stdout)
    assert summary["statuses"] == {"timeout": 2} and summary["failures_per_oracle"] == {"timeout": 2}
    suite = ET.parse(junit).getroot().find("testsuite")
    assert suite.get("errors") == "2"
    assert all(c.find("error").get("type") == "timeout" for c in suite.findall("testcase"))
