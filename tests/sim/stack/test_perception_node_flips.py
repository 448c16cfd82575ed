"""A bit flip aimed at the node `perception` lands on a site that node has, whatever the
perception mode: the learned detector's detections carry no count, so a flip drawn onto
`perception.count` would never happen (the by-node study undercounted its flips)."""

from __future__ import annotations

import pytest

from addt_dsl.compiler import compile_source
from addt_dsl.runtime.execute import execute
from addt_dsl.sweep import expand
from tests.conftest import EXAMPLES

pytestmark = pytest.mark.slow

SUITES = EXAMPLES / "suites"


def _source(fault: str) -> str:
    text = (SUITES / "bitflip_curve_perception.addt").read_text()
    text = text.replace("duration 30 s", "duration 6 s")
    return text.replace("during [2 s, 28 s] bitflip perception count flips", fault)


def _flips(stack: tuple[str, ...] = ()) -> list[str]:
    result = compile_source(_source("during [1 s, 5 s] bitflip perception count 12"), base_dir=SUITES, stack=stack)
    assert result.plan is not None, [d.message for d in result.diagnostics]
    events = [e for e in execute(expand(result.plan).specs[0]).trace.events if e.kind == "fault"]
    return [str(e.detail["location"]) for e in events]


def test_every_perception_node_flip_is_injected_with_the_learned_detector():
    pytest.importorskip("torch")
    locations = _flips()
    assert len(locations) == 12
    assert set(locations) == {"perception.x", "perception.y"}


def test_ground_truth_perception_node_flips_still_reach_the_count():
    locations = _flips(("perception=ground_truth",))
    assert len(locations) == 12 and "perception.count" in locations


def test_a_flip_on_the_count_of_a_network_that_has_none_is_refused():
    result = compile_source(_source("at 2 s bitflip perception.count"), base_dir=SUITES)
    assert result.plan is None
    assert any("perception.count" in d.message for d in result.diagnostics)
