"""The report reads the latency budget from the scenario, shows `--classify` outcome
classes, and keeps wide tables in scrolling boxes (synthetic stores, no simulation)."""

import json
import re

from tests.unit.runtime.runner_testkit import fake_record, plan_of, scenario

from addt_dsl.reporting import build_report, write_tables
from addt_dsl.reporting.tables import latency_budget_s
from addt_dsl.runtime.store import ResultStore
from addt_dsl.sweep import expand


def _plan(extra_oracles: str = ""):
    text = scenario([0, 6])
    moving = "moving: always ego.speed > 1 m/s"
    return plan_of(text.replace(moving, moving + "\n" + extra_oracles))


def test_latency_budget_comes_from_the_oracles():
    assert latency_budget_s(_plan()) is None
    assert latency_budget_s(_plan("warn fast: always latency(e2e) < 80 ms")) == 0.08
    assert latency_budget_s(_plan("p: always latency(planner) < 20 ms\n    e: always latency(e2e) <= 250 ms")) == 0.25
    assert latency_budget_s(_plan("p: always latency(planner) < 20 ms and latency(control) < 5 ms")) == 0.005


def _store(tmp_path, plan, outcome=""):
    store = ResultStore(tmp_path / "results.sqlite", plan)
    for i, spec in enumerate(expand(plan).specs):
        r = fake_record(spec, seq=i)
        r.outcome = outcome and ("masked" if i == 0 else "hazard")
        r.stats = {"latency_hist": {"e2e": {"30": 5, "45": 5}}, "latency_max_s": {"e2e": 0.091},
                   "e2e_by_objects": {"1": [10, 0.75, 0.091]}}
        store.add(r)
    return store


def test_report_and_latency_json_use_the_declared_budget(tmp_path):
    store = _store(tmp_path, _plan("warn fast: always latency(e2e) < 80 ms"))
    html = build_report(store, tmp_path / "report.html", max_animations=0).read_text()
    assert "the scenario's 80 ms budget" in html
    write_tables(tmp_path, store)
    latency = json.loads((tmp_path / "latency.json").read_text())
    assert latency["budget_ms"] == 80.0
    assert latency["nodes"]["e2e"]["share_at_or_over_budget"] == 0.5  # bins 45 (90 ms) are over 80 ms


def test_no_budget_no_line(tmp_path):
    store = _store(tmp_path, _plan())
    html = build_report(store, tmp_path / "report.html", max_animations=0).read_text()
    assert "declares no latency budget" in html
    write_tables(tmp_path, store)
    latency = json.loads((tmp_path / "latency.json").read_text())
    assert latency["budget_ms"] is None and "share_at_or_over_budget" not in latency["nodes"]["e2e"]


def test_outcome_classes_in_the_report(tmp_path):
    store = _store(tmp_path, _plan(), outcome="yes")
    html = build_report(store, tmp_path / "report.html", max_animations=0).read_text()
    outcomes = re.search(r'<div class="totals" id="outcomes">(.*?)</div>', html, re.S).group(1)
    assert '<span class="masked">masked 1</span>' in outcomes and '<span class="hazard">hazard 1</span>' in outcomes
    table = re.search(r'<table id="outcome-table">(.*?)</table>', html, re.S).group(1)
    assert table.count("<tr>") == 3  # header + one row per grid cell
    verdicts = re.search(r'<table id="verdict-table">(.*?)</table>', html, re.S).group(1)
    assert "<th>outcome</th>" in verdicts and '<td class="hazard">hazard</td>' in verdicts


def test_unclassified_report_has_no_outcome_parts(tmp_path):
    html = build_report(_store(tmp_path, _plan()), tmp_path / "report.html", max_animations=0).read_text()
    assert 'id="outcomes"' not in html and "<th>outcome</th>" not in html


def test_tables_sit_in_scrolling_boxes(tmp_path):
    html = build_report(_store(tmp_path, _plan()), tmp_path / "report.html", max_animations=0).read_text()
    for table in ("oracle-table", "cell-table", "verdict-table"):
        assert re.search(rf'<div class="scroll"[^>]*>\s*<table id="{table}">', html), table
    assert ".scroll { overflow-x: auto" in html
