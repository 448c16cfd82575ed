"""docs/faults.md: an entry per kind, and every camera ```addt-fault example corrupts a frame
(tests/docs_harness.py compiles every example and runs the others)."""

import pytest
from tests.unit.faults.faultkit import camera_frame, one

from addt_dsl.registry import FAULTS
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
    before = frame.data["image"].copy()
    out, _ = fault.on_frame(frame, 1.5)
    assert out.data["image"].shape == before.shape and (out.data["image"] != before).any()
    assert events and events[0].detail["location"] == "camera"
