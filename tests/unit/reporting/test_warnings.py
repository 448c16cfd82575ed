"""A violated `warn` oracle passes the run but is counted and shown apart everywhere:
terminal table and summary line, summary.json, runs.csv, the report, JUnit."""

import json
from xml.etree import ElementTree as ET

import pandas as pd
from tests.unit.runtime.runner_testkit import fake_record, plan_of, scenario

from addt_dsl import cli
from addt_dsl.reporting import build_report, write_junit, write_tables
from addt_dsl.reporting.tables import print_verdicts
from addt_dsl.reporting.summary import store_summary
from addt_dsl.runtime.result import Verdict
from addt_dsl.runtime.store import ResultStore
from addt_dsl.sweep import expand

PLAN = plan_of(scenario([0, 6, 7], extra="").replace(
    "moving: always ego.speed > 1 m/s", "moving: always ego.speed > 1 m/s\n    warn comfy: always ego.accel < 2 m/s^2"))


def _store(tmp_path):
    """Three runs: c000 clean, c001 passes with a warning, c002 fails and warns."""
    store = ResultStore(tmp_path / "results.sqlite", PLAN)
    for i, spec in enumerate(expand(PLAN).specs):
        r = fake_record(spec, seq=i)
        r.verdicts = [Verdict("moving", "hard", -1.0 if i == 2 else 1.0, i != 2, 0.5 if i == 2 else None),
                      Verdict("comfy", "warn", -0.3 if i else 0.4, i == 0, 1.25 if i else None)]
        store.add(r)
    return store


def test_plan_has_a_warn_oracle():
    assert [(o.name, o.severity) for o in PLAN.oracles] == [("moving", "hard"), ("comfy", "warn")]


def test_warnings_counted_apart_in_summary_and_tables(tmp_path):
    store = _store(tmp_path)
    records = list(store.records())
    assert [r.warned_oracles for r in records] == [[], ["comfy"], ["comfy"]]
    assert [r.passed for r in records] == [True, True, False]
    totals = store_summary(store)
    assert (totals["passed"], totals["failed"], totals["warned"]) == (2, 1, 2)
    assert totals["warnings_per_oracle"] == {"comfy": 2} and totals["failures_per_oracle"] == {"moving": 1}
    write_tables(tmp_path, store)
    assert json.loads((tmp_path / "summary.json").read_text())["warned"] == 2
    runs = pd.read_csv(tmp_path / "runs.csv", keep_default_na=False)
    assert runs["warned_oracles"].tolist() == ["", "comfy", "comfy"]
    assert runs["failed_oracles"].tolist() == ["", "", "moving"]


def test_terminal_line_and_colours(tmp_path, capsys, monkeypatch):
    store = _store(tmp_path)
    monkeypatch.setenv("FORCE_COLOR", "1")
    print_verdicts(PLAN, list(store.records()), store_summary(store))
    out = capsys.readouterr().out
    assert "2 passed, 1 failed, 2 with warnings" in out and "warnings per oracle: comfy 2" in out and "{'" not in out
    assert "\x1b[33m-0.3" in out  # the violated warning in yellow, not red
    assert "\x1b[31m-1" in out  # the violated hard oracle in red


def test_junit_warning_is_a_property_not_a_failure(tmp_path):
    store = _store(tmp_path)
    suite = ET.parse(write_junit(tmp_path / "j.xml", PLAN, store.records())).getroot().find("testsuite")
    assert suite.get("failures") == "1"
    cases = suite.findall("testcase")
    assert cases[1].find("failure") is None
    props = {p.get("name"): p.get("value") for p in cases[1].iter("property")}
    assert props["warning.comfy"] == "comfy: robustness -0.3 first violated at t=1.25 s"
    assert "warning: comfy" in cases[1].find("system-out").text
    assert cases[2].find("failure").get("message").startswith("moving:")


def test_report_counts_warnings(tmp_path):
    store = _store(tmp_path)
    html = build_report(store, tmp_path / "report.html", max_animations=0).read_text()
    assert 'id="warned">with warnings 2<' in html
    assert html.count('<span class="warn">(warning)</span>') == 2


def test_cli_exit_code_ignores_warnings(tmp_path, capsys):
    store = _store(tmp_path)
    store.close()
    code = cli.main(["report", str(tmp_path), "--animations", "0"])
    assert code == 1  # c002 fails its hard oracle; the warnings alone would be 0
