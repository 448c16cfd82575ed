"""Closed loop with `perception camera`: the camera detector drives the stack, and image
faults, applied to the pixels before detection, change what it does."""

from __future__ import annotations

import numpy as np
import pytest

from addt_dsl.compiler import compile_file, compile_source
from addt_dsl.studies import perception_errors
from addt_dsl.runtime.outcome import GoldenCache, classify
from addt_dsl.sweep import expand
from tests.conftest import EXAMPLES

pytestmark = pytest.mark.slow


def spec(faults: str = ""):
    src = ('scenario cam {\n  duration 12 s\n  step 10 ms\n  seed 21\n'
           '  include "families/camera_following.addt"\n'
           + (f"  faults {{\n    {faults}\n  }}\n" if faults else "") + "}\n")
    result = compile_source(src, "cam.addt", base_dir=EXAMPLES / "suites")
    assert result.ok, result.diagnostics
    return expand(result.plan).specs[0]


def detections_per_frame(result):
    return [len(e.detail["objects"]) for e in result.trace.events_of("detections")]


@pytest.fixture(scope="module")
def cache():
    return GoldenCache()


def test_the_fault_free_camera_stack_stops_behind_the_braking_lead(cache):
    result, outcome = classify(spec(), cache=cache)
    assert result.status == "ok" and result.passed, result.verdicts
    counts = detections_per_frame(result)
    assert len(counts) == 120 and counts.count(1) == 120  # 10 Hz for 12 s, the lead in every frame
    errors = [r["position_error_m"] for r in perception_errors(result.trace)]
    assert len(errors) == 120 and np.mean(errors) < 0.3
    ego, lead = result.trace.actors["ego"], result.trace.actors["lead"]
    assert ego.speed[-1] < 0.1 and lead.x[-1] - ego.x[-1] > 10.0  # stopped, well behind


def test_the_example_compiles_and_is_a_camera_stack():
    plan = compile_file(EXAMPLES / "camera_following.addt").plan
    assert plan.ego.stack.settings["perception"] == "camera"
    assert [s.name for s in plan.ego.sensors] == ["camera"]


def test_an_occluded_lens_blinds_the_detector_and_the_ego_hits_the_lead(cache):
    clean = classify(spec(), cache=cache)[0]
    result, outcome = classify(spec("occlude camera fraction 0.9"), cache=cache)
    assert result.digest != clean.digest
    counts = detections_per_frame(result)
    assert counts.count(0) > 40  # most frames after the lead gets close see nothing
    assert outcome == "hazard" and "no_collision" in result.failed_oracles
    assert any(e.kind == "collision" for e in result.trace.events)


def test_heavy_pixel_noise_makes_ghosts_and_changes_the_run_without_a_crash(cache):
    result, outcome = classify(spec("image_noise camera sigma 60"), cache=cache)
    counts = detections_per_frame(result)
    assert max(counts) >= 2  # noise blobs that pass as vehicles
    assert outcome == "silent" and result.passed


def test_mild_blur_is_masked(cache):
    result, outcome = classify(spec("blur camera sigma 1"), cache=cache)
    assert len(result.trace.events_of("fault")) == 120  # it blurred every frame...
    assert outcome == "masked"  # ...and the detector still placed the lead identically
