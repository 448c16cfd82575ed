"""`addtc FILE --classify`: the outcomes it stores are classify_many's, and its golden runs
are cached next to the store."""

from __future__ import annotations

import json

import pytest

from addt_dsl.cli import main
from addt_dsl.compiler import compile_file
from addt_dsl.runtime.outcome import GoldenCache, classify_many
from addt_dsl.runtime.store import ResultStore
from addt_dsl.sweep import expand
from tests.conftest import EXAMPLES

pytestmark = pytest.mark.slow

SCENARIO = """scenario flips {
  duration 3 s
  seed 5
  include "families/following.addt"
  param n = 1 in [1, 5]
  faults {
    during [0.5 s, 2.5 s] bitflip control count n
  }
  sweep {
    grid n in [1, 4]
    repeat 3
  }
}
"""


def test_classify_stores_classify_many_outcomes_and_reuses_golden_runs(tmp_path, capsys):
    suite = tmp_path / "suite"
    (suite / "families").mkdir(parents=True)
    (suite / "families" / "following.addt").write_text((EXAMPLES / "suites/families/following.addt").read_text())
    path = suite / "flips.addt"
    path.write_text(SCENARIO)
    out = tmp_path / "out"
    code = main([str(path), "--classify", "--jobs", "2", "--out", str(out), "--no-report"])
    err = capsys.readouterr().err
    assert "ran 3 golden run(s)" in err  # `n` only feeds the fault: both cells share 3 twins

    expected = classify_many(expand(compile_file(path).plan).specs, jobs=1, cache=GoldenCache())
    with ResultStore(out / "results.sqlite") as store:
        stored = {r.run_id: r.outcome for r in store.records()}
        assert code == (0 if all(r.passed for r in store.records()) else 1)
    assert stored == {r.run_id: o for r, o in expected}
    assert set(stored.values()) - {"masked"}  # some flips show: the comparison is not trivial

    summary = json.loads((out / "summary.json").read_text())
    kinds = ("masked", "silent", "detected", "hazard", "twin_failed", "error")
    counts = {k: list(stored.values()).count(k) for k in kinds}
    assert summary["outcomes"] == counts
    assert [c["n"] for c in summary["outcomes_per_cell"]] == [1.0, 4.0]
    assert sum(c["runs"] for c in summary["outcomes_per_cell"]) == 6
    csv = (out / "runs.csv").read_text().splitlines()
    assert csv[0].split(",")[-1] == "outcome" and len(csv) == 7

    # Again from scratch: the golden runs come from the cache beside the store.
    assert main([str(path), "--classify", "--jobs", "2", "--out", str(out), "--no-report", "--fresh"]) == code
    assert "golden run(s)" not in capsys.readouterr().err
    with ResultStore(out / "results.sqlite") as store:
        assert {r.run_id: r.outcome for r in store.records()} == stored


def test_classify_on_a_store_of_unclassified_runs_classifies_them(tmp_path, capsys):
    suite = tmp_path / "suite"
    (suite / "families").mkdir(parents=True)
    (suite / "families" / "following.addt").write_text((EXAMPLES / "suites/families/following.addt").read_text())
    path = suite / "flips.addt"
    path.write_text(SCENARIO.replace("repeat 3", "repeat 1"))
    out = tmp_path / "out"
    code = main([str(path), "--jobs", "1", "--out", str(out), "--no-report"])
    with ResultStore(out / "results.sqlite") as store:
        before = {r.run_id: (r.digest, r.passed) for r in store.records()}
        assert {r.outcome for r in store.records()} == {""}
    capsys.readouterr()
    assert main([str(path), "--classify", "--jobs", "1", "--out", str(out), "--no-report"]) == code
    assert "2 stored run(s) have no outcome class" in capsys.readouterr().err
    expected = classify_many(expand(compile_file(path).plan).specs, jobs=1, cache=GoldenCache())
    with ResultStore(out / "results.sqlite") as store:
        assert {r.run_id: r.outcome for r in store.records()} == {r.run_id: o for r, o in expected}
        assert {r.run_id: (r.digest, r.passed) for r in store.records()} == before
    assert (out / "runs.csv").read_text().splitlines()[0].split(",")[-1] == "outcome"
