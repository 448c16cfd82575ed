"""A printed run replays bit for bit: same RunSpec, same trace digest."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.unit.search.search_testkit import kitchen_sink_plan

from addt_dsl.compiler import compile_file
from addt_dsl.printer import compile_pinned, pin_spec, print_spec
from addt_dsl.runtime.execute import execute
from addt_dsl.sweep import expand

ROOT = Path(__file__).resolve().parents[2]

pytestmark = pytest.mark.slow


@pytest.mark.parametrize("which", ["ten_faults", "kitchen_sink"])
def test_pinned_file_replays_the_same_trace(which, tmp_path):
    plan = compile_file(ROOT / "examples" / "ten_faults.addt").plan if which == "ten_faults" else kitchen_sink_plan()
    spec = expand(plan).specs[-1]
    path = tmp_path / "pinned.addt"
    path.write_text(print_spec(spec))
    replay = compile_pinned(path.read_text(), path=str(path), base_dir=tmp_path)
    digests = {execute(s, keep_trace=False).digest for s in (spec, pin_spec(spec), replay)}
    assert len(digests) == 1
