"""Results are tied to the code that made them: keys, store plan hashes and the search's run
cache carry the code fingerprint (package version, learned weights, latency model)."""

from __future__ import annotations

import hashlib

import pytest
from tests.unit.runtime.runner_testkit import fake_record, plan_of, scenario

from addt_dsl import fingerprint
from addt_dsl.runtime.store import ResultStore, StoreMismatch
from addt_dsl.search.cache import RunCache
from addt_dsl.sweep import expand

PLAN = plan_of(scenario([0, 1], repeat=1))
SPECS = expand(PLAN).specs


@pytest.fixture
def other_code(monkeypatch):
    """Run the test body as a later version of the package would."""
    def switch():
        identity = dict(fingerprint._identity())
        monkeypatch.setattr(fingerprint, "_identity", lambda: tuple({**identity, "addt-dsl": "9.9"}.items()))
    return switch


def test_the_fingerprint_names_the_version_and_hashes_the_stack_data():
    identity = fingerprint.code_identity()
    assert set(identity) == {"addt-dsl", *fingerprint.DATA_FILES, "source"}
    for name in fingerprint.DATA_FILES:
        digest = hashlib.sha256((fingerprint.PACKAGE_DIR / name).read_bytes()).hexdigest()
        assert digest.startswith(identity[name])


def test_keys_change_with_the_code(other_code):
    before = [s.key() for s in SPECS]
    other_code()
    assert all(a != b for a, b in zip(before, (s.key() for s in SPECS)))


def test_a_store_made_by_other_code_is_refused_with_what_differs(tmp_path, other_code):
    path = tmp_path / "r.sqlite"
    with ResultStore(path, PLAN) as store:
        store.add(fake_record(SPECS[0], seq=0))
    with ResultStore(path, PLAN) as store:  # same code: resumes
        assert len(store) == 1
    other_code()
    with pytest.raises(StoreMismatch, match=r"made by other code \(addt-dsl .*; this is addt-dsl 9\.9.*--fresh"):
        ResultStore(path, PLAN)
    with ResultStore(path, PLAN, fresh=True) as store:  # --fresh: the runs are made again
        assert len(store) == 0 and store.done() == set()


def _judge(spec):
    return fake_record(spec)


def test_the_search_cache_reruns_what_other_code_made(tmp_path, other_code):
    path = tmp_path / "cache.sqlite"
    first = RunCache(path, evaluator=_judge)
    first.get(SPECS[0])
    first.close()
    again = RunCache(path, evaluator=_judge)
    again.get(SPECS[0])
    assert (again.simulations, again.hits) == (0, 1)
    again.close()
    other_code()
    later = RunCache(path, evaluator=_judge)
    later.get(SPECS[0])
    assert (later.simulations, later.hits) == (1, 0)


def test_the_fingerprint_changes_with_the_source_that_runs_a_spec(tmp_path, monkeypatch):
    """An editable install keeps its version across edits: a change to the stack's or the
    loop's source must still make other code (a stale run cache would be reused otherwise)."""
    names = {p.relative_to(fingerprint.PACKAGE_DIR).as_posix() for p in fingerprint.source_files()}
    assert {"runtime/execute.py", "stack/nodes.py", "runtime/faults/base.py", "plan.py"} <= names
    assert not any(n == "cli.py" or n.startswith(("compiler/", "reporting/")) for n in names)
    real = fingerprint.code_identity()
    copy = tmp_path / "addt_dsl"
    for name in [*names, *fingerprint.DATA_FILES]:
        (copy / name).parent.mkdir(parents=True, exist_ok=True)
        (copy / name).write_bytes((fingerprint.PACKAGE_DIR / name).read_bytes())
    monkeypatch.setattr(fingerprint, "PACKAGE_DIR", copy)

    def identity():
        fingerprint._identity.cache_clear()
        return fingerprint.code_identity()

    try:
        before = identity()
        assert before == real  # the copy is the same code
        (copy / "stack/nodes.py").write_text((copy / "stack/nodes.py").read_text() + "\n# an edit\n")
        after = identity()
        assert after["source"] != before["source"]
        assert {k: v for k, v in after.items() if k != "source"} == {k: v for k, v in before.items() if k != "source"}
    finally:
        fingerprint._identity.cache_clear()


def test_a_rerun_that_differs_says_when_the_store_was_made_by_other_code(tmp_path, other_code):
    from addt_dsl.reporting.trace_view import RunTrace, stored_by_other_code

    path = tmp_path / "r.sqlite"
    with ResultStore(path, PLAN) as store:
        store.add(fake_record(SPECS[0], seq=0))
    with ResultStore(path) as store:
        assert stored_by_other_code(store) == ""
        differs = RunTrace(None, SPECS[0], None, [], reproduced=False)
        assert differs.mismatch().endswith("not reproducible")
        assert RunTrace(None, SPECS[0], None, [], reproduced=True).mismatch() == ""
        other_code()  # this process is now a later version than the store's
        made_by = stored_by_other_code(store)
        assert "addt-dsl" in made_by and "9.9" not in made_by
        message = RunTrace(None, SPECS[0], None, [], reproduced=False, other_code=made_by).mismatch()
        assert "made by other code" in message and "this is addt-dsl 9.9" in message
