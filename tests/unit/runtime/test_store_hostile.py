"""Results stores that SQLite reads but addtc did not write as they are: rows and plans
edited or damaged by something else, stores of another schema, and a run cache mixed with
a sweep's store. Each is one line and a documented exit code (docs/running.md), never an
"internal error", and never runs of two plans mixed in one report. Stores are built from
fake records (no simulation)."""

import shutil
import sqlite3

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from tests.unit.runtime.runner_testkit import fake_record, plan_of, scenario

from addt_dsl import cli
from addt_dsl.compiler import compile_source
from addt_dsl.errors import EXIT_INCOMPLETE, EXIT_OK, EXIT_USAGE
from addt_dsl.limits import DEFAULT
from addt_dsl.printer import check_spec
from addt_dsl.runtime.result import Verdict
from addt_dsl.runtime.store import ResultStore, StoreError, StoreMismatch
from addt_dsl.sweep import expand

PLAN = plan_of(scenario([0, 6]))


def _store(path, plan=PLAN):
    with ResultStore(path, plan) as store:
        for i, spec in enumerate(expand(plan).specs):
            r = fake_record(spec, seq=i)
            if i:
                r.verdicts = [Verdict("moving", "hard", -1.0, False, 0.1)]
            store.add(r)
    return path


@pytest.fixture(scope="module")
def good(tmp_path_factory):
    return _store(tmp_path_factory.mktemp("good") / "r.sqlite")


def _damaged(good, tmp_path, *sql):
    path = tmp_path / "r.sqlite"
    shutil.copy(good, path)
    with sqlite3.connect(path) as db:
        for statement in sql:
            db.execute(statement)
    db.close()
    return path


def _one_line(capsys, *words):
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err and "internal error" not in err, err
    for word in words:
        assert word in err, err
    return err


FIRST = "(SELECT MIN(rowid) FROM runs)"
ROWS = {
    "verdicts_not_json": f"UPDATE runs SET verdicts = '{{garbage' WHERE rowid = {FIRST}",
    "verdicts_wrong_shape": f"UPDATE runs SET verdicts = '[{{\"x\": 1}}]' WHERE rowid = {FIRST}",
    "params_not_json": f"UPDATE runs SET params = '[1, 2' WHERE rowid = {FIRST}",
    "params_a_list": f"UPDATE runs SET params = '[1, 2]' WHERE rowid = {FIRST}",
    "cell_of_a_list": f"UPDATE runs SET cell = '{{\"mode\": []}}' WHERE rowid = {FIRST}",
    "stats_not_json": f"UPDATE runs SET stats = 'nope' WHERE rowid = {FIRST}",
    "injections_bad_key": f"UPDATE runs SET injections = '{{\"events\": {{\"a\": 1}}}}' WHERE rowid = {FIRST}",
    "seq_text": f"UPDATE runs SET seq = 'abc' WHERE rowid = {FIRST}",
}


@pytest.mark.parametrize("damage", sorted(ROWS))
def test_a_damaged_row_is_named_and_salvage_leaves_it_out(damage, good, tmp_path, capsys):
    path = _damaged(good, tmp_path, ROWS[damage])
    assert cli.main(["report", str(path), "--out", str(tmp_path / "rep")]) == EXIT_INCOMPLETE
    _one_line(capsys, "is damaged (run 'c000-r000' cannot be read", "--salvage NEW.sqlite")
    # The remedy works: the readable run is copied, the damaged one is left for a resume to run.
    assert cli.main(["report", str(path), "--salvage", str(tmp_path / "new.sqlite")]) == EXIT_OK
    assert "1 unreadable run(s) left out" in capsys.readouterr().out
    with ResultStore(tmp_path / "new.sqlite", readonly=True) as store:
        assert [r.run_id for r in store.records()] == ["c001-r000"]


@pytest.mark.parametrize(("sql", "words"), [
    ("UPDATE meta SET value = '{\"nope\": 1}' WHERE name = 'plan'",
     ("its plan cannot be read", "writes the plan again")),
    ("UPDATE meta SET value = replace(value, '\"schema_version\":\"2\"', '\"schema_version\":\"1\",\"x\":1') "
     "WHERE name = 'plan'", ("plan of schema '1', made by another version of addtc",)),
    ("INSERT OR REPLACE INTO meta VALUES ('rejected', '[[')", ("its 'rejected' entry is not a JSON dict",)),
    ("INSERT OR REPLACE INTO meta VALUES ('not_done', '{{')", ("its 'not_done' entry is not a JSON list",)),
    ("UPDATE meta SET value = '9' WHERE name = 'schema'", ("of schema '9', made by another version of addtc",)),
])
def test_damaged_or_foreign_meta_is_one_line(sql, words, good, tmp_path, capsys):
    path = _damaged(good, tmp_path, sql)
    assert cli.main(["report", str(path), "--out", str(tmp_path / "rep")]) == EXIT_INCOMPLETE
    _one_line(capsys, *words)


def test_a_damaged_plan_is_written_again_by_the_sweep(good, tmp_path):
    path = _damaged(good, tmp_path, "UPDATE meta SET value = '{}' WHERE name = 'plan'")
    with ResultStore(path, PLAN):  # what `addtc FILE --store PATH` does first
        pass
    with ResultStore(path, readonly=True) as store:
        assert store.plan() == PLAN and len(list(store.records())) == 2


def test_a_store_of_another_schema_is_never_written(good, tmp_path):
    path = _damaged(good, tmp_path, "UPDATE meta SET value = '9' WHERE name = 'schema'")
    before = path.read_bytes()
    for open_it in (lambda: ResultStore(path, PLAN), lambda: ResultStore(path, PLAN, fresh=True),
                    lambda: ResultStore.cache(path)):
        with pytest.raises(StoreError, match="schema '9'"):
            open_it()
    assert path.read_bytes() == before


@pytest.mark.parametrize("spec", ["xx", "{}", "[1]"])
def test_trace_of_a_damaged_run_spec_is_one_line(spec, good, tmp_path, capsys):
    path = _damaged(good, tmp_path, f"UPDATE runs SET spec = '{spec}'")
    assert cli.main(["trace", str(path), "c000-r000"]) == EXIT_INCOMPLETE
    _one_line(capsys, "the RunSpec of run 'c000-r000' cannot be read")


def test_a_run_cache_and_a_sweep_store_are_never_mixed(good, tmp_path, capsys):
    sweep = tmp_path / "sweep.sqlite"
    shutil.copy(good, sweep)
    # A sweep's store given as a run cache: refused, not filled with another plan's runs.
    with pytest.raises(StoreMismatch, match="results store of a sweep of 'guards', not a run cache"):
        ResultStore.cache(sweep)
    with ResultStore(sweep, readonly=True) as store:
        assert len(store) == 2
    # A run cache given as a sweep's store: refused unless --fresh.
    cache_path = tmp_path / "cache.sqlite"
    other = plan_of(scenario([1]))
    with ResultStore.cache(cache_path) as cache:
        cache.add(fake_record(expand(other).specs[0]), other)
    with pytest.raises(StoreMismatch, match="holds 1 run\\(s\\) but no plan: it is a run cache"):
        ResultStore(cache_path, PLAN)
    with ResultStore(cache_path, PLAN, fresh=True) as store:
        assert len(store) == 0
    # `addtc report` of a run cache says what it is.
    cache2 = tmp_path / "cache2.sqlite"
    with ResultStore.cache(cache2) as cache:
        cache.add(fake_record(expand(other).specs[0]), other)
    assert cli.main(["report", str(cache2), "--out", str(tmp_path / "rep")]) == EXIT_INCOMPLETE
    _one_line(capsys, "holds no plan: it is a run cache")


def test_the_cli_refuses_to_mix_them(good, tmp_path, capsys):
    path = tmp_path / "s.addt"
    path.write_text(scenario([0]))
    cache_path = tmp_path / "cache.sqlite"
    other = plan_of(scenario([1]))
    with ResultStore.cache(cache_path) as cache:
        cache.add(fake_record(expand(other).specs[0]), other)
    assert cli.main([str(path), "--executor", "inline", "--store", str(cache_path), "--no-report"]) == EXIT_USAGE
    err = capsys.readouterr().err  # the compiler's warning (an unused parameter), then the one line
    assert err.strip().splitlines()[-1].startswith("error: ") and "it is a run cache" in err and "Traceback" not in err


COLUMNS = ["key", "run_id", "seq", "session", "status", "passed", "seed", "repeat_index", "params", "cell",
           "spec", "verdicts", "failed_oracles", "sim_time_s", "wall_time_s", "digest", "fault_events", "error",
           "stats", "worker", "outcome", "injections", "plan_hash"]
VALUES = st.one_of(st.none(), st.integers(-2**63, 2**63 - 1), st.floats(allow_nan=True), st.text(max_size=12),
                   st.sampled_from(["{}", "[]", "null", "{\"a\": 1}", "[{}]", "[[]]", "1e999", "NaN", "\"x\"",
                                    "{\"events\": []}", "{\"drawn\": {\"0\": 5}}"]))


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(column=st.sampled_from(COLUMNS), value=VALUES)
def test_any_value_in_any_column_is_a_report_or_one_line(good, tmp_path_factory, capsys, column, value):
    """Fuzz: one cell of a stored run replaced by any value SQLite takes: the report either
    works or says the store is damaged; never an internal error or a traceback."""
    tmp = tmp_path_factory.mktemp("fuzz")
    path = tmp / "r.sqlite"
    shutil.copy(good, path)
    with sqlite3.connect(path) as db:
        try:
            db.execute(f"UPDATE runs SET {column} = ? WHERE rowid = {FIRST}", (value,))
        except sqlite3.IntegrityError:  # NOT NULL: SQLite itself refuses it
            return
    db.close()
    capsys.readouterr()
    code = cli.main(["report", str(path), "--out", str(tmp / "rep"), "--animations", "0"])
    err = capsys.readouterr().err
    assert "Traceback" not in err and "internal error" not in err, (column, value, err)
    assert code in (0, 1, 3), (column, value, err)


def test_trace_of_a_run_edited_beyond_a_scenario_is_one_line(good, tmp_path, capsys):
    """A stored plan edited to a duration of 1e308 s: `addtc trace` re-ran it and said
    'internal error: OverflowError'; now it is checked as a scenario first."""
    with ResultStore(good, readonly=True) as store:
        plan = store.plan().model_copy(update={"duration_s": 1e308})
    path = _damaged(good, tmp_path, "DELETE FROM plans")
    with sqlite3.connect(path) as db:
        db.execute("UPDATE meta SET value = ? WHERE name = 'plan'", (plan.model_dump_json(),))
    db.close()
    assert cli.main(["trace", str(path), "c000-r000"]) == EXIT_INCOMPLETE
    err = capsys.readouterr().err
    assert err.startswith(f"error: {path}: run c000-r000 is not one a scenario can state") and "E0301" in err


def test_trace_checks_a_run_of_raised_limits_as_the_sweep_made_it():
    """A sweep run with `--max agents=N` makes runs beyond the default limits: `trace`
    checks values, not sizes."""
    agents = "\n".join(f"  agent a{i} car on r lane -1 at {30 + 5 * i} m speed 5 m/s" for i in range(12))
    text = scenario([0]).replace("  expect {", agents + "\n  expect {")
    few = DEFAULT.raised(agents=10)
    plan = compile_source(text, limits=few.raised(agents=12)).plan
    spec = expand(plan).specs[0]
    with pytest.raises(ValueError, match="agents"):
        check_spec(spec, few)
    check_spec(spec, cli._ANY_SIZE)
