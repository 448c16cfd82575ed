"""docs/faults.md: an entry per kind, and every ```addt-fault example compiles (or, for camera
kinds before the camera sensor exists, applies to a synthetic frame)."""

import pytest
from tests.unit.faults.faultkit import camera_frame, one

from addt_dsl.compiler import compile_source
from addt_dsl.registry import FAULTS, SENSORS
from tests.faults_doc import DOC, IMAGE_KINDS, LINES, ROOT, kind_of, scenario


def test_every_kind_has_an_entry_and_an_example():
    for cls in FAULTS.classes():
        assert f"### {cls.keyword}\n" in DOC, cls.keyword
        assert any(kind_of(line) == cls.keyword for line in LINES), cls.keyword


@pytest.mark.parametrize("line", [ln for ln in LINES if kind_of(ln) not in IMAGE_KINDS or "camera" in SENSORS])
def test_doc_example_compiles(line):
    result = compile_source(scenario(line), "doc.addt", base_dir=ROOT / "examples" / "suites")
    assert result.ok, [d.message for d in result.diagnostics]
    (fault,) = result.plan.faults
    assert fault.kind == kind_of(line)


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
