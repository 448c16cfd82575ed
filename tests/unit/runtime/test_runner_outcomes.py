"""Outcome classes in the store, the tables and the CLI wiring of `--classify` (no simulation:
records are made by hand, the executor runs a fake run function)."""

from __future__ import annotations

import json
import math
import sqlite3

import pytest
from tests.unit.runtime.runner_testkit import fake_record, plan_of, scenario

from addt_dsl.reporting.summary import store_dataframe, store_summary
from addt_dsl.reporting.tables import runs_table, summary
from addt_dsl.runtime.executor import LocalExecutor, run_sweep
from addt_dsl.runtime.outcome import ClassifyingExecutor, ClassifyingRun
from addt_dsl.runtime.store import ResultStore
from addt_dsl.sweep import expand

PLAN = plan_of(scenario([0, 6], repeat=3))


def records(outcomes: list[str]):
    out = []
    for spec, outcome in zip(expand(PLAN).specs, outcomes):
        r = fake_record(spec)
        r.outcome = outcome
        if outcome == "hazard":
            r.verdicts[0].passed = False
        out.append(r)
    return out


def test_summary_counts_outcomes_and_tabulates_them_per_grid_cell():
    recs = records(["masked", "silent", "hazard", "twin_failed", "detected", "error"])
    s = summary(PLAN, recs)
    assert s["outcomes"] == {"masked": 1, "silent": 1, "detected": 1, "hazard": 1, "twin_failed": 1, "error": 1}
    cells = {c["mode"]: c for c in s["outcomes_per_cell"]}
    assert set(cells) == {0.0, 6.0}
    assert (cells[0.0]["masked"], cells[0.0]["silent"], cells[0.0]["hazard"], cells[0.0]["runs"]) == (1, 1, 1, 3)
    assert cells[0.0]["success_rate"] == pytest.approx(2 / 3)
    # Rates are over runs whose twin passed: a twin_failed run or a runner error is no sample.
    assert cells[0.0]["fault_samples"] == 3 and cells[0.0]["hazard_rate"] == pytest.approx(1 / 3)
    assert 0 < cells[0.0]["hazard_lo"] < 1 / 3 < cells[0.0]["hazard_hi"] < 1
    six = cells[6.0]
    assert (six["twin_failed"], six["detected"], six["error"], six["fault_samples"]) == (1, 1, 1, 1)
    assert cells[6.0]["detected_rate"] == 1.0 and cells[6.0]["hazard_rate"] == 0.0
    json.dumps(s, allow_nan=False)  # plain JSON types, no NaN


def test_unclassified_runs_add_no_outcome_fields():
    recs = records([""] * 6)
    assert "outcomes" not in summary(PLAN, recs)
    assert "outcome" not in runs_table(PLAN, recs).columns
    assert list(runs_table(PLAN, records(["masked"] * 6))["outcome"]) == ["masked"] * 6


def test_the_store_keeps_outcomes_and_upgrades_an_old_store(tmp_path):
    path = tmp_path / "r.sqlite"
    with ResultStore(path, PLAN) as store:
        pass
    # A store written before outcomes existed: the same table without the column.
    db = sqlite3.connect(path)
    db.execute("CREATE TABLE old AS SELECT * FROM runs")
    db.execute("DROP TABLE runs")
    db.execute("ALTER TABLE old DROP COLUMN outcome")
    db.execute("ALTER TABLE old RENAME TO runs")
    db.commit()
    db.close()
    with ResultStore(path, PLAN) as store:
        for r in records(["silent", "hazard", "", "masked", "masked", "masked"]):
            store.add(r)
    with ResultStore(path) as store:
        assert [r.outcome for r in store.records()] == ["silent", "hazard", "", "masked", "masked", "masked"]
        assert store_summary(store)["outcomes"] == {"masked": 3, "silent": 1, "detected": 0, "hazard": 1,
                                                   "twin_failed": 0, "error": 0}
        assert list(store_dataframe(store)["outcome"]) == ["silent", "hazard", "", "masked", "masked", "masked"]


def _crash(spec, seq=-1, worker=""):
    raise RuntimeError("worker lost")


def test_runs_the_executor_could_not_finish_are_errors(tmp_path):
    executor = ClassifyingExecutor(LocalExecutor(1, start_method="fork"), tmp_path / "r.sqlite")
    assert isinstance(executor.inner.run_fn, ClassifyingRun)
    executor.inner.run_fn = _crash  # the worker's run fails: the executor records it itself
    with ResultStore(tmp_path / "r.sqlite", PLAN) as store:
        run_sweep(expand(PLAN).specs[:1], store, executor)
        [record] = list(store.records())
    assert (record.status, record.outcome) == ("crashed", "error")


def test_classify_is_refused_on_executors_that_cannot_run_it(tmp_path):
    class Remote:
        name, workers = "ray", 4

    with pytest.raises(ValueError, match="cannot classify"):
        ClassifyingExecutor(Remote(), tmp_path)


def _judged(spec, status: str, passed: bool):
    r = fake_record(spec)
    r.status = status
    r.verdicts[0].passed = passed
    return r


def test_a_run_whose_fault_free_twin_fails_is_never_a_hazard():
    from addt_dsl.runtime.outcome import Fingerprint, outcome_of

    spec = expand(PLAN).specs[0]
    failing_twin = Fingerprint({}, "ok", passed=False)
    # However the faulty run ends (failed, passed, stack stopped), the twin's failure decides.
    assert outcome_of(_judged(spec, "ok", passed=False), failing_twin) == "twin_failed"
    assert outcome_of(_judged(spec, "ok", passed=True), failing_twin) == "twin_failed"
    assert outcome_of(_judged(spec, "detected", passed=True), failing_twin) == "twin_failed"
    # A twin the stack stopped fails too; a crashed twin is the runner's error.
    assert outcome_of(_judged(spec, "ok", passed=False), Fingerprint({}, "detected", passed=False)) == "twin_failed"
    assert outcome_of(_judged(spec, "ok", passed=False), Fingerprint({}, "crashed", passed=False)) == "error"
    # With a passing twin, a stack that stopped is detected.
    assert outcome_of(_judged(spec, "detected", passed=True), Fingerprint({}, "ok", passed=True)) == "detected"


def test_wilson_interval_brackets_the_rate():
    from addt_dsl.runtime.outcome import wilson_interval

    lo, hi = wilson_interval(0, 40)
    assert lo == pytest.approx(0.0, abs=1e-12) and 0.05 < hi < 0.1  # 0 of 40: up to ~8.8 %
    lo, hi = wilson_interval(20, 40)
    assert lo == pytest.approx(0.352, abs=1e-3) and hi == pytest.approx(0.648, abs=1e-3)
    assert all(math.isnan(x) for x in wilson_interval(0, 0))


def test_a_classified_run_gives_a_stored_unclassified_one_its_outcome_and_nothing_else(tmp_path):
    with ResultStore(tmp_path / "r.sqlite", PLAN) as store:
        plain = records([""] * 6)
        for r in plain:
            store.add(r)
        assert store.done(classified=True) == set() and len(store.done()) == 6
        again = records(["masked", "hazard", "", "", "", ""])
        assert store.add(again[0]) and store.add(again[1])  # gained a class
        assert not store.add(again[0])  # already classified: nothing changes
        assert not store.add(again[2])  # no class to give
        assert {rid for _, rid in store.done(classified=True)} == {again[0].run_id, again[1].run_id}
        stored = {r.run_id: r for r in store.records()}
    assert stored[again[0].run_id].outcome == "masked" and stored[again[1].run_id].outcome == "hazard"
    assert len(stored) == 6 and stored[again[1].run_id].passed == plain[1].passed  # the row is not replaced
