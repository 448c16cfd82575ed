"""docs/faults.md: an entry per kind, and every camera ```addt-fault example corrupts a frame
(tests/docs_harness.py compiles every example and runs the others)."""

import numpy as np
import pytest
from tests.unit.runtime.faults.faultkit import camera_frame, one

from addt_dsl.registry import FAULTS
from addt_dsl.runtime.sensors import Frame
from tests.docs_harness import FAULT_LINES as LINES
from tests.docs_harness import IMAGE_KINDS, ROOT, kind_of

DOC = (ROOT / "docs" / "faults.md").read_text()


def test_every_kind_has_an_entry_and_an_example():
    for cls in FAULTS.classes():
        assert f"### {cls.keyword}\n" in DOC, cls.keyword
        assert any(kind_of(line) == cls.keyword for line in LINES), cls.keyword


@pytest.mark.parametrize("line", [ln for ln in LINES if kind_of(ln) in IMAGE_KINDS])
def test_camera_doc_example_corrupts_a_synthetic_frame(line):
    words = line.split()
    start = words.index(kind_of(line))
    kind, target, rest = words[start], words[start + 1], words[start + 2:]
    settings = {k: float(v) for k, v in zip(rest[::2], rest[1::2])}
    fault, events = one(kind, target=target, **settings)
    frame = camera_frame()
    if target == "camera_rig":  # its images, K x H x W x 3
        frame = Frame("camera_rig", 0.0, {"images": np.stack([frame.data["image"]] * 3)})
    key = "images" if target == "camera_rig" else "image"
    before = frame.data[key].copy()
    out, _ = fault.on_frame(frame, 1.5)
    assert out.data[key].shape == before.shape and (out.data[key] != before).any()
    assert events and events[0].detail["location"].split(".")[0] == target
