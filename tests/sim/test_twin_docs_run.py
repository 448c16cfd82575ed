"""The .addt examples in docs/twin.md run as written."""

import re
from pathlib import Path

import pytest

from addt_dsl.compiler import compile_source
from addt_dsl.runtime.execute import execute
from addt_dsl.sweep import expand

pytestmark = pytest.mark.slow
ROOT = Path(__file__).resolve().parents[2]
BLOCKS = re.findall(r"```addt\n(.*?)```", (ROOT / "docs" / "twin.md").read_text(encoding="utf-8"), flags=re.S)


@pytest.mark.parametrize("source", BLOCKS, ids=[re.search(r"scenario (\w+)", b).group(1) for b in BLOCKS])
def test_twin_doc_example_runs(source):
    result = compile_source(source, path="docs/twin.md", base_dir=ROOT / "tests" / "data" / "xodr")
    assert result.plan is not None, [str(d) for d in result.diagnostics]
    out = execute(expand(result.plan).specs[0])
    assert out.status == "ok", out.error
    assert out.sim_time_s == pytest.approx(result.plan.duration_s)
    assert out.passed, out.failed_oracles
