"""The closed-loop helpers the sim tests share: compile a scenario's text and run the first
spec of its sweep."""

from __future__ import annotations

from pathlib import Path

from addt_dsl.compiler import compile_source
from addt_dsl.runtime.execute import execute
from addt_dsl.sweep import expand


def first_run(source: str, path: str = "<input>", base_dir: str | Path = "."):
    """The result of the first run of `source`'s sweep, whatever the run's status; the
    source must compile without an error (warnings allowed)."""
    result = compile_source(source, path, base_dir=base_dir)
    assert result.ok, [str(d) for d in result.diagnostics]
    return execute(expand(result.plan).specs[0])


def run(source: str, path: str = "<input>", base_dir: str | Path = "."):
    """The trace of the first run of `source`'s sweep, which must end without an error."""
    out = first_run(source, path, base_dir)
    assert out.status == "ok", out.error
    return out.trace


# Runs of the default settings, by the whole RunSpec (its key leaves out display names and
# the run id, which the result carries): a spec determines its run bit for bit (the
# project's rule, checked by tests/sim/runtime/test_batch.py and test_hash_seed.py), so
# tests that need the same run alone as their reference share one (every example's first
# run: the batch tests and the OpenSCENARIO round trip). Only for tests that patch nothing
# a run reads; results are shared: read them, never change them.
_SOLO: dict[str, object] = {}


def solo(spec):
    """`execute(spec)`, once per test session."""
    key = spec.model_dump_json()
    if key not in _SOLO:
        _SOLO[key] = execute(spec)
    return _SOLO[key]
