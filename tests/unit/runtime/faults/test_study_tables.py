"""Success tables of fault studies rate only runs whose fault-free twin passed:
`addtc study table` on a classified runs.csv and the suite table of `addtc --classify --by`."""

import csv
from types import SimpleNamespace

import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from addt_dsl import cli

from addt_dsl.runtime.outcome import wilson_interval
from addt_dsl.studies import success_table
from addt_dsl.suite import tally_by


def runs_csv(rows):
    return pd.DataFrame([{"param.rate": r, "passed": p, **({"outcome": o} if o is not None else {})}
                         for r, p, o in rows])


def test_a_classified_table_leaves_out_runs_whose_twin_failed():
    rows = ([(0.1, True, "masked")] * 6 + [(0.1, False, "hazard")] * 2 + [(0.1, False, "twin_failed")] * 3
            + [(0.1, True, "twin_failed")] + [(0.1, False, "error")]
            + [(0.2, True, "silent")] * 4 + [(0.2, False, "detected")])
    table = success_table(runs_csv(rows), ["rate"])
    a, b = table.loc[0.1], table.loc[0.2]
    assert (a["runs"], a["twin_failed"], a["error"], a["n"], a["passed"], a["hazard"]) == (13, 4, 1, 8, 6, 2)
    assert a["success_rate"] == pytest.approx(6 / 8)
    assert (a["lo"], a["hi"]) == pytest.approx(wilson_interval(6, 8))
    assert (b["n"], b["passed"], b["twin_failed"]) == (5, 4, 0)
    assert b["success_rate"] == pytest.approx(0.8)


def test_an_unclassified_table_rates_every_run_with_an_interval():
    table = success_table(runs_csv([(0.1, True, None)] * 9 + [(0.1, False, None)]), ["rate"])
    row = table.loc[0.1]
    assert (row["runs"], row["passed"], row["success_rate"]) == (10, 9, pytest.approx(0.9))
    assert (row["lo"], row["hi"]) == pytest.approx(wilson_interval(9, 10))
    assert "twin_failed" not in table.columns
    # An outcome column that `addtc` left empty (runs not classified) is the same table.
    empty = runs_csv([(0.1, True, None)] * 9 + [(0.1, False, None)]).assign(outcome=float("nan"))
    assert success_table(empty, ["rate"]).equals(table)


def test_the_suite_table_rates_classified_runs_over_those_whose_twin_passed():
    def rec(passed, outcome):
        return SimpleNamespace(cell={"rate": 0.1}, params={"rate": 0.1}, passed=passed, outcome=outcome)

    (t,) = tally_by([rec(True, "masked")] * 3 + [rec(False, "hazard"), rec(False, "twin_failed")], "rate").values()
    assert (t.runs, t.passed, t.samples, t.samples_passed, t.rate) == (5, 3, 4, 3, 0.75)
    d = t.as_dict()
    assert (d["fault_samples"], d["fault_samples_passed"], d["outcomes"]["twin_failed"]) == (4, 3, 1)
    assert d["interval95"] == pytest.approx(list(wilson_interval(3, 4)))
    (plain,) = tally_by([rec(True, "")] * 3 + [rec(False, "")], "rate").values()
    assert (plain.rate, "fault_samples" in plain.as_dict()) == (0.75, False)


def test_the_outcome_table_rates_success_over_runs_whose_twin_passed():
    from addt_dsl.runtime.outcome import outcome_table

    def rec(passed):
        return SimpleNamespace(params={"flips": 1}, cell={}, passed=passed, fault_events=1)

    pairs = [(rec(True), "masked")] * 3 + [(rec(False), "hazard"), (rec(True), "twin_failed"),
                                           (rec(False), "twin_failed"), (rec(False), "error")]
    row = outcome_table(pairs, by=["flips"]).loc[1]
    assert (row["runs"], row["fault_samples"], row["twin_failed"]) == (7, 4, 2)
    assert row["success_rate"] == pytest.approx(3 / 4)
    assert (row["success_lo"], row["success_hi"]) == pytest.approx(wilson_interval(3, 4))


CELLS = ["", "nan", "inf", "-inf", "1e308", "x", "True", "False", "0", "-1", '"', ",", "None", "[]", "masked",
         "hazard", "twin_failed", "\x00"]


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(edits=st.lists(st.tuples(st.integers(0, 12), st.integers(0, 4), st.sampled_from(CELLS)), min_size=1,
                      max_size=4))
def test_any_damaged_runs_csv_is_a_table_or_one_line(tmp_path, capsys, edits):
    """Fuzz: cells of a classified runs.csv replaced by hostile text (a user file): `addtc study
    table` prints a table (0) or one line (2), never an internal error or a traceback."""
    rows = [["param.rate", "passed", "outcome", "run_id", "seed"]]
    rows += [[str(0.1 * (i % 3)), str(i % 4 != 0), ("masked", "hazard", "twin_failed")[i % 3], f"c{i:03d}-r000",
              str(i)] for i in range(12)]
    for i, j, value in edits:
        rows[i][j] = value
    path = tmp_path / "runs.csv"
    with path.open("w", newline="") as fh:
        csv.writer(fh).writerows(rows)
    capsys.readouterr()
    code = cli.main(["study", "table", str(path), "--by", "rate"])
    err = capsys.readouterr().err
    assert code in (0, 2) and "internal error" not in err and "Traceback" not in err, err
