"""The SQLite results store: round trips, resume bookkeeping, plan binding, durability, exports."""

import math
import os
import signal
import subprocess
import sys
import textwrap

import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from tests.conftest import ROOT
from tests.unit.runtime.runner_testkit import OK, fake_record, plan_of, scenario

from addt_dsl.reporting.summary import store_dataframe, store_summary, write_csv, write_parquet
from addt_dsl.reporting.tables import summary
from addt_dsl.runtime.result import RunResult, Verdict
from addt_dsl.runtime.store import ResultStore, StoreMismatch
from addt_dsl.sweep import expand

PLAN = plan_of(scenario([0, 1, 2], repeat=2))
SPECS = expand(PLAN).specs


def _record(spec, i: int) -> RunResult:
    r = fake_record(spec, seq=i, worker="w")
    r.verdicts = [Verdict("moving", "hard", [math.inf, -2.5, 0.75][i % 3], i % 3 != 1,
                          1.5 if i % 3 == 1 else None),
                  Verdict("soft", "warn", -math.inf, False, 0.0)]
    r.stats = {"latency_hist": {"e2e": {"3": 10, "60": 2}}, "latency_max_s": {"e2e": 0.121},
               "e2e_by_objects": {"2": [12, 0.5, 0.121]}}
    r.sim_time_s, r.wall_time_s = 0.2, 0.01 * i
    return r


def _comparable(r: RunResult) -> dict:
    d = dict(vars(r))
    d.pop("session")
    return d


def test_records_round_trip_exactly(tmp_path):
    written = [_record(s, i) for i, s in enumerate(SPECS)]
    with ResultStore(tmp_path / "r.sqlite", PLAN) as store:
        store.begin_session("test", "inline", 1)
        for r in written:
            assert store.add(r)
    with ResultStore(tmp_path / "r.sqlite") as store:  # reopened without the plan: it is stored
        read = list(store.records())
        assert store.plan() == PLAN
        assert {r.session for r in read} == {1}
    assert [_comparable(r) for r in read] == [_comparable(r) for r in written]


def test_rebuilt_spec_is_the_same_run(tmp_path):
    with ResultStore(tmp_path / "r.sqlite", PLAN) as store:
        for i, s in enumerate(SPECS):
            store.add(_record(s, i))
        for record, spec in zip(store.records(), SPECS):
            rebuilt = store.spec(record)
            assert rebuilt == spec
            assert rebuilt.key() == record.key == spec.key()


def test_duplicates_are_ignored_and_done_lists_stored_runs(tmp_path):
    with ResultStore(tmp_path / "r.sqlite", PLAN) as store:
        assert store.add(_record(SPECS[0], 0))
        assert not store.add(_record(SPECS[0], 0))
        assert len(store) == 1
        assert store.done() == {(SPECS[0].key(), SPECS[0].run_id)}


def test_a_store_is_bound_to_one_plan(tmp_path):
    other = plan_of(scenario([OK], repeat=3))
    with ResultStore(tmp_path / "r.sqlite", PLAN) as store:
        store.add(_record(SPECS[0], 0))
    with pytest.raises(StoreMismatch, match="--fresh"):
        ResultStore(tmp_path / "r.sqlite", other)
    with ResultStore(tmp_path / "r.sqlite", other, fresh=True) as store:
        assert len(store) == 0
        assert store.plan() == other
    with pytest.raises(FileNotFoundError):
        ResultStore(tmp_path / "missing.sqlite")


def test_summary_matches_the_records(tmp_path):
    with ResultStore(tmp_path / "r.sqlite", PLAN) as store:
        for i, s in enumerate(SPECS):
            store.add(_record(s, i))
        crashed = RunResult.unfinished(expand(plan_of(scenario([OK]))).specs[0], "crashed", "x", 0.0)
        crashed.key, crashed.run_id = "other", "c999-r000"
        store.add(crashed)
        records = list(store.records())
        assert store_summary(store) == summary(PLAN, records)
        assert store_summary(store)["failures_per_oracle"] == {"crashed": 1, "moving": 2}


def test_dataframe_csv_and_parquet(tmp_path):
    with ResultStore(tmp_path / "r.sqlite", PLAN) as store:
        for i, s in enumerate(SPECS):
            store.add(_record(s, i))
        df = store_dataframe(store)
        write_csv(store, tmp_path / "runs.csv")
        write_parquet(store, tmp_path / "runs.parquet")
    assert len(df) == len(SPECS)
    for column in ("run_id", "param.mode", "seed", "passed", "rho.moving", "first_violation_s.moving",
                   "sim_time_s", "wall_time_s"):
        assert column in df.columns
    assert df["rho.moving"].tolist()[:3] == [math.inf, -2.5, 0.75]
    back = pd.read_parquet(tmp_path / "runs.parquet")
    pd.testing.assert_frame_equal(back, df)
    csv = pd.read_csv(tmp_path / "runs.csv")
    assert csv["run_id"].tolist() == df["run_id"].tolist()
    assert csv["passed"].tolist() == df["passed"].tolist()


def test_committed_runs_survive_sigkill(tmp_path):
    """A process killed right after its commits leaves exactly those runs, intact."""
    path = tmp_path / "r.sqlite"
    code = textwrap.dedent(f"""
        import os, signal, sys
        sys.path.insert(0, {str(ROOT)!r})
        from tests.unit.runtime.runner_testkit import fake_record, plan_of, scenario
        from addt_dsl.runtime.store import ResultStore
        from addt_dsl.sweep import expand
        plan = plan_of(scenario([0, 1, 2], repeat=2))
        store = ResultStore({str(path)!r}, plan)
        for i, spec in enumerate(expand(plan).specs[:4]):
            store.add(fake_record(spec, seq=i))
        store._db.execute("BEGIN IMMEDIATE")  # an open, uncommitted transaction at the kill
        store._db.execute("DELETE FROM runs")
        os.kill(os.getpid(), signal.SIGKILL)
    """)
    proc = subprocess.run([sys.executable, "-c", code], env={**os.environ})
    assert proc.returncode == -signal.SIGKILL
    with ResultStore(path) as store:
        assert store._db.execute("PRAGMA integrity_check").fetchone() == ("ok",)
        assert [r.run_id for r in store.records()] == [s.run_id for s in SPECS[:4]]


@settings(max_examples=25, deadline=None)
@given(st.lists(st.integers(0, len(SPECS) - 1), max_size=20))
def test_any_add_sequence_stores_each_run_once(tmp_path_factory, picks):
    path = tmp_path_factory.mktemp("prop") / "r.sqlite"
    with ResultStore(path, PLAN) as store:
        added = [store.add(_record(SPECS[i], i)) for i in picks]
        assert sum(added) == len(set(picks))
        assert sorted(r.run_id for r in store.records()) == sorted({SPECS[i].run_id for i in picks})
