"""`report.html` animates failing runs only on request (`--animations N`) and within a wall
time budget (a 6-failure sweep took 97.7 s instead of 18.8 s with GIFs always drawn);
`latency.json` never shows a percentile above the worst latency (p50 was a bin's upper
edge, above max). Synthetic stores, no simulation."""

import itertools
import json

from tests.unit.runtime.runner_testkit import fake_record, plan_of, scenario

from addt_dsl import cli
from addt_dsl.reporting import build_report, html, write_tables
from addt_dsl.runtime.result import Verdict
from addt_dsl.runtime.store import ResultStore
from addt_dsl.sweep import expand

PLAN = plan_of(scenario([0, 6, 7]))


def _failing_store(tmp_path):
    store = ResultStore(tmp_path / "results.sqlite", PLAN)
    for i, spec in enumerate(expand(PLAN).specs):
        r = fake_record(spec, seq=i)
        r.verdicts = [Verdict("moving", "hard", -1.0 - i, False, 0.5)]
        r.stats = {"latency_hist": {"e2e": {"0": 10}}, "latency_max_s": {"e2e": 0.0008}}
        store.add(r)
    return store


def test_no_animation_unless_asked(tmp_path, monkeypatch):
    store = _failing_store(tmp_path)
    calls = []
    monkeypatch.setattr(html, "_animate", lambda store, r: calls.append(r.run_id))
    text = build_report(store, tmp_path / "report.html").read_text()
    assert calls == [] and "animations are off by default" in text
    assert cli.main(["report", str(tmp_path)]) == 1 and calls == []
    help_text = cli.build_parser()._subparsers._group_actions[0].choices["report"].format_help()
    assert "--animations N" in help_text and "worst failing runs" in help_text


def test_requested_animations_stop_at_the_time_budget(tmp_path, monkeypatch):
    store = _failing_store(tmp_path)
    clock = itertools.count(0.0, 40.0)  # each animation takes 40 s of the 60 s budget
    monkeypatch.setattr(html, "_animate", lambda store, r: r.run_id)
    animations, skipped = html._animations(store, list(store.records()), 60.0, clock=lambda: next(clock))
    assert animations == ["c000-r000", "c001-r000"] and skipped == ["c002-r000"]
    animations, skipped = html._animations(store, list(store.records()), 0.0, clock=lambda: next(clock))
    assert len(animations) == 1 and len(skipped) == 2  # at least one when asked for


def test_latency_percentiles_never_exceed_the_worst(tmp_path):
    write_tables(tmp_path, _failing_store(tmp_path))
    e2e = json.loads((tmp_path / "latency.json").read_text())["nodes"]["e2e"]
    assert e2e["max_ms"] == 0.8
    assert e2e["p50_ms"] <= e2e["max_ms"] and e2e["p99_ms"] <= e2e["max_ms"]
