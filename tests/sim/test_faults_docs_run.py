"""Every non-camera ```addt-fault example of docs/faults.md fires in a short closed-loop run."""

import pytest

from addt_dsl.compiler import compile_source
from addt_dsl.runtime.execute import execute
from addt_dsl.sweep import expand
from tests.faults_doc import IMAGE_KINDS, LINES, ROOT, kind_of, scenario

pytestmark = pytest.mark.slow


@pytest.mark.parametrize("line", [ln for ln in LINES if kind_of(ln) not in IMAGE_KINDS])
def test_doc_example_injects_and_records(line):
    result = compile_source(scenario(line), "doc.addt", base_dir=ROOT / "examples" / "suites")
    assert result.ok
    run = execute(expand(result.plan).specs[0])
    events = [e for e in run.trace.events if e.kind == "fault"]
    assert events, "the example never fired"
    assert {e.detail["kind"] for e in events} == {kind_of(line)}
    assert all({"location", "value"} <= set(e.detail) for e in events)
