"""Every scenario in the docs runs, every run of its sweep, with the verdicts its block states
(```addt expect="..."); every non-camera fault line of docs/faults.md fires in a short run."""

import pytest

from addt_dsl.compiler import compile_source
from addt_dsl.runtime.execute import execute, execute_batch
from addt_dsl.runtime.executor import BATCH_MAX
from addt_dsl.sweep import expand
from tests.docs_harness import (
    FAULT_LINES,
    IMAGE_KINDS,
    blocks,
    fault_scenario,
    ids,
    kind,
    kind_of,
    normalise,
    scenario_dir,
    verdicts,
)

pytestmark = pytest.mark.slow
SCENARIOS = [b for b in blocks("addt") if kind(b) == "scenario"]


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    return scenario_dir(tmp_path_factory.mktemp("scenarios"))


@pytest.mark.parametrize("block", SCENARIOS, ids=ids(SCENARIOS))
def test_doc_scenario_gives_its_stated_verdicts(block, base):
    result = compile_source(block.text, block.doc, base_dir=base)
    assert result.ok, [str(d) for d in result.diagnostics]
    # In batches, as `addtc` steps a sweep (a run's result does not depend on its batch:
    # tests/sim/runtime/test_batch.py); 144 runs of docs/language.md took 1.6x as long alone.
    specs = expand(result.plan).specs
    runs = [r for j in range(0, len(specs), BATCH_MAX) for r in execute_batch(specs[j:j + BATCH_MAX])]
    # A run ends early at a collision, or where its `end when` fires.
    ended_early = [r.run_id for r in runs if r.passed and r.sim_time_s < result.plan.duration_s - 1e-9
                   and not any(e.kind == "end" for e in r.trace.events)]
    assert not ended_early, "a run stopped early (the ego collided) and passed: expect `no collision`"
    assert str(verdicts(runs)) == normalise(block.attrs["expect"])


@pytest.mark.parametrize("line", [ln for ln in FAULT_LINES if kind_of(ln) not in IMAGE_KINDS])
def test_doc_fault_line_injects_and_records(line, base):
    result = compile_source(fault_scenario(line), "docs/faults.md", base_dir=base)
    assert result.ok
    run = execute(expand(result.plan).specs[0])
    events = [e for e in run.trace.events if e.kind == "fault"]
    assert events, "the example never fired"
    assert {e.detail["kind"] for e in events} == {kind_of(line)}
    assert all({"location", "value"} <= set(e.detail) for e in events)
