"""Workers step batches of runs (`LocalExecutor(batch=N)`): the records are those of runs
stepped one by one, a resumed sweep skips what the store holds, and a batch that does not
finish (a hung, crashing or memory-hogging run in it) is isolated: each of its runs goes
again alone, so only the guilty run is recorded as failed."""

from collections import Counter

from tests.unit.runtime.runner_testkit import HANG, HOG, OK, RAISE, SEGFAULT, fake_record, fake_run, plan_of, scenario

from addt_dsl import cli
from addt_dsl.runtime import executor as executor_module
from addt_dsl.runtime.executor import LocalExecutor, default_batch, run_local, run_sweep
from addt_dsl.runtime.store import ResultStore
from addt_dsl.sweep import SweepStream


def test_a_failing_run_in_a_batch_fails_alone(tmp_path):
    plan = plan_of(scenario([OK, HANG, OK, SEGFAULT, OK, HOG, RAISE, OK]))
    store = ResultStore(tmp_path / "r.sqlite", plan)
    executor = LocalExecutor(2, timeout_s=1.0, memory_limit_mb=250, run_fn=fake_run, retries=0, batch=4)
    outcome = run_sweep(SweepStream(plan), store, executor)
    records = list(store.records())
    assert len(records) == outcome.ran == 8
    by_mode = Counter((int(r.cell["mode"]), r.status) for r in records)
    assert by_mode == Counter({(OK, "ok"): 4, (HANG, "timeout"): 1, (SEGFAULT, "crashed"): 1,
                               (HOG, "memory"): 1, (RAISE, "crashed"): 1})
    errors = {int(r.cell["mode"]): r.error for r in records}
    assert "1 s timeout" in errors[HANG] and "batch" not in errors[HANG]  # its own bound, alone
    assert "signal 11" in errors[SEGFAULT]


def test_batched_records_equal_one_by_one_and_resume_skips(tmp_path):
    plan = plan_of(scenario([0, 2], repeat=4, duration="0.3 s"))  # real closed-loop runs
    one = run_local(SweepStream(plan), jobs=1)
    batched = run_local(SweepStream(plan), jobs=2, batch=3)
    key = lambda r: (r.run_id, r.status, r.digest, repr(r.verdicts))  # noqa: E731
    assert [key(r) for r in batched] == [key(r) for r in one]
    assert len({r.digest for r in one}) > 1
    # A store that holds three runs: a batched sweep runs the other five only.
    store = ResultStore(tmp_path / "r.sqlite", plan)
    for r in one[:3]:
        store.add(r)
    outcome = run_sweep(SweepStream(plan), store, LocalExecutor(1, batch=4))
    assert (outcome.skipped, outcome.ran) == (3, 5)
    assert sorted(key(r) for r in store.records()) == sorted(key(r) for r in one)


def test_default_batch_from_the_sweep_size():
    assert default_batch(64, 1) == 16  # capped
    assert default_batch(40, 2) == 5  # each worker 4 batches
    assert default_batch(3, 2) == 1
    assert default_batch(0, 4) == 1


def _batches_made(monkeypatch, executor: str) -> list:
    """The `batch` each new `executor` (a class of the executor module) is made with, as made."""
    made = []
    real = getattr(executor_module, executor)

    def spy(*args, **kwargs):
        made.append(kwargs.get("batch"))
        return real(*args, **kwargs)

    monkeypatch.setattr(executor_module, executor, spy)
    return made


def test_cli_batch_reaches_the_executor(tmp_path, monkeypatch):
    made = _batches_made(monkeypatch, "LocalExecutor")
    path = tmp_path / "s.addt"
    path.write_text(scenario([0, 2], repeat=3, duration="0.2 s"))
    assert cli.main([str(path), "--jobs", "1", "--batch", "4", "--store", str(tmp_path / "a.sqlite")]) == 0
    assert cli.main([str(path), "--jobs", "1", "--store", str(tmp_path / "b.sqlite")]) == 0
    assert made == [4, 1]  # given; the default for 6 runs on one worker
    with ResultStore(tmp_path / "a.sqlite", plan_of(path.read_text())) as a, \
            ResultStore(tmp_path / "b.sqlite", plan_of(path.read_text())) as b:
        assert sorted((r.run_id, r.digest) for r in a.records()) == sorted((r.run_id, r.digest) for r in b.records())


class DropsRaising:
    """A batched run function (`run_batch`) that returns no record for a RAISE run."""

    def __call__(self, spec, seq: int = -1, worker: str = ""):
        return self.run_batch([spec], [seq], worker)[0]

    def run_batch(self, specs, seqs, worker: str = ""):
        return [fake_record(s, q, worker) for s, q in zip(specs, seqs) if int(s.params["mode"]) != RAISE]


def test_a_run_without_a_record_is_recorded_crashed_never_left_out():
    """Every dispatched run yields exactly one record: one a batched run function dropped is
    `crashed`, and the others keep their own seqs (zipping the batch with fewer records
    filed them under their neighbours')."""
    plan = plan_of(scenario([OK, RAISE, OK, OK, RAISE, OK]))
    specs = list(SweepStream(plan))
    for executor in (LocalExecutor(2, run_fn=DropsRaising(), retries=1, batch=3),
                     executor_module.InlineExecutor(DropsRaising(), batch=3)):
        records = sorted(executor.imap(enumerate(specs)), key=lambda r: r.seq)
        assert [r.seq for r in records] == list(range(6))
        assert [r.key for r in records] == [s.key() for s in specs]
        assert [r.status for r in records] == ["ok", "crashed", "ok", "ok", "crashed", "ok"]
        assert "none for this one" in records[1].error


def test_an_inline_batch_past_its_bound_runs_each_alone():
    """`InlineExecutor(batch=N)`: a batch past its bound (the sum of its runs') is not judged;
    each run goes again alone under its own bound, so only the hung one is `timeout`."""
    plan = plan_of(scenario([OK, HANG, OK, OK]))
    specs = list(SweepStream(plan))
    records = list(executor_module.InlineExecutor(fake_run, timeout_s=0.3, batch=4).imap(enumerate(specs)))
    assert [(r.seq, r.status) for r in records] == [(0, "ok"), (1, "timeout"), (2, "ok"), (3, "ok")]
    assert "0.3 s timeout" in records[1].error


def test_cli_batch_reaches_the_inline_executor(tmp_path, monkeypatch):
    made = _batches_made(monkeypatch, "InlineExecutor")
    path = tmp_path / "s.addt"
    path.write_text(scenario([0, 2], repeat=4, duration="0.2 s"))
    for name, extra in (("a", ["--batch", "3"]), ("b", [])):
        assert cli.main([str(path), "--executor", "inline", *extra, "--store", str(tmp_path / f"{name}.sqlite")]) == 0
    assert made == [3, 2]  # given; the default for 8 runs in one process
    with ResultStore(tmp_path / "a.sqlite", plan_of(path.read_text())) as a, \
            ResultStore(tmp_path / "b.sqlite", plan_of(path.read_text())) as b:
        assert sorted((r.run_id, r.digest) for r in a.records()) == sorted((r.run_id, r.digest) for r in b.records())
