"""End-of-sweep tables are streamed: the outcome table aggregates with running
counters and the runs table is written in chunks, yet both equal what pandas makes of all
rows at once (the reference implementations below are the whole-frame pandas versions)."""

import math

import pandas as pd
from hypothesis import given, settings
from hypothesis import strategies as st
from tests.unit.runtime.runner_testkit import fake_record, plan_of, scenario

from addt_dsl.reporting.summary import write_csv, write_parquet
from addt_dsl.reporting.tables import runs_table
from addt_dsl.runtime.outcome import FAULT_OUTCOMES, OUTCOMES, outcome_table, wilson_interval
from addt_dsl.runtime.result import Verdict
from addt_dsl.runtime.store import ResultStore
from addt_dsl.sweep import expand


def _reference_outcome_table(pairs, by):
    """The table as a pandas groupby over one row per run computes it."""
    rows = [{**{p: r.params.get(p, r.cell.get(p)) for p in by}, "outcome": o, "passed": r.passed,
             "fault_events": r.fault_events} for r, o in pairs]
    df = pd.DataFrame(rows)
    if df.empty:
        return df
    keys = list(by) or (lambda _: 0)
    counts = df.groupby(keys)["outcome"].value_counts().unstack(fill_value=0)
    for name in (*OUTCOMES, "error"):
        if name not in counts:
            counts[name] = 0
    table = counts[[*OUTCOMES, "error"]].copy()
    grouped = df.groupby(keys)["passed"]
    table["runs"] = grouped.size()
    n = table[list(FAULT_OUTCOMES)].sum(axis=1)
    df["ok"] = df["passed"].astype(bool) & df["outcome"].isin(FAULT_OUTCOMES)  # passed, twin passed
    ok = df.groupby(keys)["ok"].sum()
    table["success_rate"] = [k / m if m else math.nan for k, m in zip(ok, n)]
    bounds = [wilson_interval(k, m) for k, m in zip(ok, n)]
    table["success_lo"] = [lo for lo, _ in bounds]
    table["success_hi"] = [hi for _, hi in bounds]
    table["fault_events"] = df.groupby(keys)["fault_events"].mean()
    table["fault_samples"] = n
    for name in FAULT_OUTCOMES:
        bounds = [wilson_interval(k, m) for k, m in zip(table[name], n)]
        table[f"{name}_rate"] = [k / m if m else math.nan for k, m in zip(table[name], n)]
        table[f"{name}_lo"] = [lo for lo, _ in bounds]
        table[f"{name}_hi"] = [hi for _, hi in bounds]
    return table


PLAN = plan_of(scenario([0, 1, 2, 3, 4, 5, 6, 7], repeat=3))  # 24 distinct runs
SPECS = expand(PLAN).specs
CLASSES = ["masked", "silent", "detected", "hazard", "twin_failed", "error", ""]

run = st.fixed_dictionaries({
    "a": st.sampled_from([0.0, 0.5, 1.0, math.nan, None]),
    "b": st.sampled_from([1.0, 2.0]),
    "passed": st.booleans(),
    "fault_events": st.integers(0, 5),
    "outcome": st.sampled_from(CLASSES),
})


@settings(max_examples=150, deadline=None)
@given(runs=st.lists(run, min_size=0, max_size=30),
       by=st.sampled_from([(), ("a",), ("b",), ("a", "b"), ("b", "a")]))
def test_streamed_outcome_table_equals_the_pandas_groupby(runs, by):
    pairs = []
    for i, d in enumerate(runs):
        r = fake_record(SPECS[i % len(SPECS)], seq=i)
        r.params = {k: d[k] for k in ("a", "b") if d[k] is not None}
        r.cell = {}
        r.verdicts = [Verdict("moving", "hard", 1.0 if d["passed"] else -1.0, d["passed"], None)]
        r.fault_events = d["fault_events"]
        assert r.passed == d["passed"]
        pairs.append((r, d["outcome"]))
    expected = _reference_outcome_table(pairs, by)
    got = outcome_table(iter(pairs), by)  # a generator: read once
    if len(expected) == 0 and len(pairs):  # every run dropped (NaN group): no rows, same columns
        assert got.empty and list(got.columns) == list(expected.columns)
        assert list(got.index.names) == list(expected.index.names)
        return
    pd.testing.assert_frame_equal(got, expected, check_index_type=True, check_column_type=True)


def _records(n: int, mixed: bool):
    """Runs whose columns vary: some lack a parameter or an oracle (mixed), ints and floats in
    one column, infinite robustness, errors and outcomes."""
    out = []
    for i in range(n):
        r = fake_record(SPECS[i % len(SPECS)], seq=i, worker="w")
        r.verdicts = [Verdict("moving", "hard", [math.inf, -2.5, 0.75][i % 3], i % 3 != 1,
                              1.5 if i % 3 == 1 else None)]
        if mixed and i % 4 == 3:
            r.verdicts.append(Verdict("late", "warn", -1.0, False, 0.25))
        if mixed:
            r.params = dict(r.params, extra=(i if i % 5 else 0.5)) if i % 7 else dict(r.params)
        r.error = "boom\nsecond line" if i % 6 == 5 else ""
        r.outcome = "masked" if mixed and i % 2 else ""
        r.sim_time_s, r.wall_time_s = 0.2, 0.01 * i
        out.append(r)
    return out


def test_streamed_csv_and_parquet_equal_the_whole_frame(tmp_path):
    for mixed in (False, True):
        path = tmp_path / f"r{mixed}.sqlite"
        with ResultStore(path, PLAN) as store:
            for r in _records(23, mixed):
                assert store.add(r)
            whole = runs_table(PLAN, store.records())
            # chunks of 4 rows: many chunks, some without the odd rows
            write_csv(store, tmp_path / "runs.csv", chunk=4)
            write_parquet(store, tmp_path / "runs.parquet", chunk=4)
        assert (tmp_path / "runs.csv").read_text() == whole.to_csv(index=False)
        pd.testing.assert_frame_equal(pd.read_parquet(tmp_path / "runs.parquet"), whole)
        assert ("outcome" in whole.columns) == mixed


def test_an_empty_store_writes_empty_tables(tmp_path):
    with ResultStore(tmp_path / "r.sqlite", PLAN) as store:
        write_csv(store, tmp_path / "runs.csv")
        assert (tmp_path / "runs.csv").read_text() == runs_table(PLAN, []).to_csv(index=False)
