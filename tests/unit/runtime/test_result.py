"""`RunResult` decides pass / fail / warn in one place, for every status."""

from __future__ import annotations

import math

import pytest

from addt_dsl.plan import RunSpec
from addt_dsl.runtime.result import STACK_HEALTH, RunResult, Verdict
from addt_dsl.runtime.store import ResultStore
from addt_dsl.sweep import expand
from tests.conftest import EXAMPLES


@pytest.fixture(scope="module")
def spec() -> RunSpec:
    from addt_dsl.compiler import compile_file

    return expand(compile_file(EXAMPLES / "overtake.addt").plan).specs[0]


def _result(spec, status="ok", error="", hard=True, warn=True) -> RunResult:
    r = RunResult.unfinished(spec, status, error, 0.0)
    r.sim_time_s = 4.0
    r.verdicts = [Verdict("no_collision", "hard", 1.0 if hard else -0.5, hard, None if hard else 2.0, "m"),
                  Verdict("comfort", "warn", 0.2 if warn else -0.1, warn, None if warn else 1.0)]
    return r


def test_a_violated_warn_oracle_is_a_warning_not_a_failure(spec):
    r = _result(spec, warn=False)
    assert r.passed and r.failed_oracles == [] and r.warned_oracles == ["comfort"] and r.failures == ()


def test_a_violated_hard_oracle_fails_with_its_identity(spec):
    r = _result(spec, hard=False, warn=False)
    assert not r.passed and r.failed_oracles == ["no_collision"] and r.warned_oracles == ["comfort"]
    assert [f.id for f in r.failures] == [("no_collision", "m")] and r.primary().time_s == 2.0


@pytest.mark.parametrize("status, error, failed, mode, time_s", [
    ("detected", "FloatingPointError: nan command", STACK_HEALTH, "FloatingPointError", 4.0),
    ("crashed", "RuntimeError: boom\ntraceback", "crashed", "crash RuntimeError", None),
    ("timeout", "run exceeded the 5 s timeout", "timeout", "crash timeout", None),
    ("memory", "resident memory 5000 MB", "memory", "crash memory", None),
])
def test_a_run_that_did_not_end_normally_fails(spec, status, error, failed, mode, time_s):
    r = _result(spec, status, error)
    assert not r.passed and r.failed_oracles == [failed]
    [f] = r.failures
    assert (f.oracle, f.mode, f.time_s, f.robustness) == (STACK_HEALTH, mode, time_s, -math.inf)


def test_the_store_keeps_what_decides_the_verdict(spec, tmp_path):
    r = _result(spec, hard=False, warn=False)
    r.injections, r.drawn_values = {0: 3}, {0: (61, 62, 61)}
    with ResultStore(tmp_path / "r.sqlite", spec.plan) as store:
        store.add(r)
        [back] = list(store.records())
    assert back.verdicts == r.verdicts
    assert (back.failed_oracles, back.warned_oracles, back.failures) == (r.failed_oracles, r.warned_oracles, r.failures)
    assert (back.injections, back.drawn_values) == (r.injections, r.drawn_values)
