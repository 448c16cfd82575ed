"""Tables, JUnit XML and the HTML report over synthetic stores (no simulation)."""

import base64
import math
import re
from xml.etree import ElementTree as ET

from hypothesis import given
from hypothesis import strategies as st
from tests.unit.runtime.runner_testkit import fake_record, plan_of, scenario

from addt_dsl.reporting import build_report, write_junit
from addt_dsl.reporting.summary import store_summary
from addt_dsl.reporting.tables import cell_stats, success_pivot
from addt_dsl.stats import wilson_interval
from addt_dsl.runtime.result import RunResult, Verdict
from addt_dsl.runtime.store import ResultStore
from addt_dsl.sweep import expand

PLAN = plan_of(scenario([0, 6, 7], repeat=4))


def _records():
    out = []
    for i, spec in enumerate(expand(PLAN).specs):
        r = fake_record(spec, seq=i)
        mode = int(spec.params["mode"])
        failing = mode == 6 and spec.repeat_index < 3  # cell 6: 1 of 4 passes; 0 and 7 all pass
        r.verdicts = [Verdict("moving", "hard", -0.5 - i if failing else 0.5 + i, not failing,
                                    1.25 if failing else None)]
        r.stats = {"latency_hist": {"e2e": {"40": 5, "55": 1}, "planner": {"4": 6}},
                   "latency_max_s": {"e2e": 0.111, "planner": 0.009},
                   "e2e_by_objects": {"1": [3, 0.24, 0.09], "3": [3, 0.33, 0.111]}}
        out.append(r)
    spec = expand(PLAN).specs[-1]
    crashed = RunResult.unfinished(spec, "timeout", "run exceeded the 5 s timeout", 5.0, seq=99)
    crashed.run_id = "c009-r000"
    crashed.key = "k-timeout"
    out.append(crashed)
    return out


def _store(tmp_path):
    store = ResultStore(tmp_path / "r.sqlite", PLAN)
    for r in _records():
        store.add(r)
    return store


def test_cell_success_rates_and_pivot():
    stats = cell_stats(_records())
    assert [(s.cell, s.runs, s.passed) for s in stats] == [
        ({"mode": 0.0}, 4, 4), ({"mode": 6.0}, 4, 1), ({"mode": 7.0}, 5, 4)]
    assert stats[1].rate == 0.25
    pivot = success_pivot(PLAN, stats)
    assert pivot["col_axis"] == "mode" and pivot["columns"] == ["0", "6", "7"]
    assert [c.passed for c in pivot["rows"][0]["cells"]] == [4, 1, 4]


@given(st.integers(0, 200), st.integers(0, 200))
def test_wilson_interval_contains_the_rate(a, b):
    n, k = max(a, b), min(a, b)
    lo, hi = wilson_interval(k, n)
    if n:
        assert 0.0 <= lo <= hi <= 1.0
        assert lo - 1e-12 <= k / n <= hi + 1e-12
    else:  # no runs: no rate, and no interval
        assert math.isnan(lo) and math.isnan(hi)


def test_junit_has_one_testcase_per_run_with_failure_details(tmp_path):
    store = _store(tmp_path)
    path = write_junit(tmp_path / "junit.xml", PLAN, store.records())
    root = ET.parse(path).getroot()
    suite = root.find("testsuite")
    cases = suite.findall("testcase")
    assert len(cases) == len(store) == 13
    assert (suite.get("tests"), suite.get("failures"), suite.get("errors")) == ("13", "3", "1")
    failures = [c for c in cases if c.find("failure") is not None]
    assert all(c.get("classname") == "guards[mode=6]" for c in failures)
    message = failures[0].find("failure").get("message")
    assert re.fullmatch(r"moving: robustness -[\d.]+ first violated at t=1\.25 s", message)
    error = next(c for c in cases if c.find("error") is not None).find("error")
    assert error.get("type") == "timeout" and "5 s timeout" in error.get("message")
    props = {p.get("name"): p.get("value") for p in cases[0].find("properties")}
    assert props["param.mode"] == "0.0" and float(props["robustness.moving"]) > 0


def test_html_report_is_escaped_and_self_contained(tmp_path):
    store = _store(tmp_path)
    html = build_report(store, tmp_path / "report.html", max_animations=0).read_text()
    assert "<script>alert(1)</script>" not in html  # the plan's description, autoescaped
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in html
    assert not re.search(r"""(src|href)=["'](https?:|//)""", html)  # nothing fetched from outside
    table = re.search(r'<table id="verdict-table">(.*?)</table>', html, re.S).group(1)
    assert table.count("<tr>") == 1 + 13
    pngs = re.findall(r'src="data:image/png;base64,([^"]+)"', html)
    assert len(pngs) >= 4  # success chart, robustness, latency per node, latency vs objects
    assert all(base64.b64decode(p).startswith(b"\x89PNG") for p in pngs)
    assert 'alt="latency distributions per node"' in html
    assert 'alt="latency against object count"' in html
    assert "25.00 %" in html  # cell mode=6: 1 of 4 passed
    assert store_summary(store)["failed"] == 3  # oracle failures; the timed-out run is an error
    assert store_summary(store)["errors"] == 1
    assert re.search(r"errors 1</span>", html)
