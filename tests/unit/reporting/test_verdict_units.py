"""The verdict table says what its numbers are: each oracle's robustness with its unit
(`reach_goal 149` is metres, `latency_budget -0.22` seconds), a legend, and a totals line
that is words, not a Python dict."""

from __future__ import annotations

from tests.unit.runtime.runner_testkit import fake_record

from addt_dsl.compiler import compile_file, compile_source
from addt_dsl.reporting.summary import store_summary
from addt_dsl.reporting.tables import VERDICT_LEGEND, print_verdicts, robustness_unit, totals_line
from addt_dsl.runtime.result import Verdict
from addt_dsl.runtime.store import ResultStore
from addt_dsl.sweep import expand
from tests.conftest import ROOT


def test_each_oracle_has_the_unit_of_its_comparisons():
    plan = compile_file(ROOT / "examples" / "overtake.addt").plan
    got = {o.name: robustness_unit(plan, o.formula) for o in plan.oracles}
    assert got == {"no_collision": "m", "lane_keeping": "m", "safe_headway": "s", "latency_budget": "s",
                   "reach_goal": "m"}


def test_mixed_or_uncertain_units_show_none():
    source = """scenario mixed {
  duration 5 s
  road r {
    line length 200 m
  }
  param v = 10 m/s in [5 m/s, 15 m/s]
  ego car on r lane -1 at 10 m speed v
  agent lead car on r lane -1 at 40 m speed 10 m/s
  expect {
    both: always gap(ego, lead) > 5 m and speed(ego) < 30 m/s
    scaled: always 2 * gap(ego, lead) / speed(lead) > -1 s
    ratio: always gap(ego, lead) / speed(ego) > 1 s
    over_param: always speed(ego) < v + 5 m/s
  }
}
"""
    plan = compile_source(source, path="mixed.addt").plan
    got = {o.name: robustness_unit(plan, o.formula) for o in plan.oracles}
    assert got == {"both": "", "scaled": "", "ratio": "s", "over_param": "m/s"}


def test_the_table_has_units_a_legend_and_no_dict(tmp_path, capsys):
    plan = compile_file(ROOT / "examples" / "overtake.addt").plan
    store = ResultStore(tmp_path / "results.sqlite", plan)
    for i, spec in enumerate(expand(plan).specs):
        r = fake_record(spec, seq=i)
        r.verdicts = [Verdict(o.name, o.severity, -1.0 if i == 2 and o.name == "reach_goal" else 1.0,
                              not (i == 2 and o.name == "reach_goal"), None) for o in plan.oracles]
        store.add(r)
    totals = store_summary(store)
    print_verdicts(plan, list(store.records()), totals)
    out = capsys.readouterr().out
    for header in ("no_collision [m]", "safe_headway [s]", "latency_budget [s]", "reach_goal [m]"):
        assert header in out
    assert VERDICT_LEGEND[:40] in out.replace("\n", " ")
    assert "failures per oracle: reach_goal 1" in totals_line(totals) and "{" not in totals_line(totals)
