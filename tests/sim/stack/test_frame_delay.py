"""A delayed frame shows the world as it was when it was captured: its detections are the
ground truth at its stamp, mapped out through the ego's pose at its stamp, whenever it
arrives (`delay`: "frames arrive late", docs/faults.md)."""

import numpy as np
import pytest

from tests.sim.kit import run

pytestmark = pytest.mark.slow

LIDAR = "sensor lidar rate 10 Hz rays 360 channels 5 vfov 12 deg range 80 m"


def source(perception: str, faults: str) -> str:
    # Ego and lead at 15 m/s: in 100 ms each moves 1.5 m.
    return f"""scenario delayed {{
  duration 2.5 s
  road r {{
    line length 500 m
    lanes right 1 width 3.5 m
  }}
  ego car on r lane -1 at 20 m speed 15 m/s {{
    stack bev {perception} cruise_speed 15 m/s
    {LIDAR}
  }}
  agent lead car on r lane -1 at 50 m speed 15 m/s {{
    behavior cruise speed 15 m/s
  }}
  faults {{
    {faults}
  }}
}}"""


def detections(trace) -> dict[float, list]:
    """stamp [s] -> the objects [x, y, heading] perception reported from that frame."""
    return {round(e.detail["stamp_s"], 6): e.detail["objects"] for e in trace.events
            if e.kind == "detections"}


def test_ground_truth_perception_of_a_delayed_frame_is_the_world_at_its_capture():
    trace = run(source("perception_noise 0 m", "during [1 s, 2 s] delay lidar by 100 ms"))
    lead = trace.actors["lead"]
    delayed = {s: o for s, o in detections(trace).items() if 1.0 <= s <= 2.0}
    assert len(delayed) >= 10
    for stamp, objs in delayed.items():
        k = int(np.searchsorted(trace.time, stamp - 1e-9))
        (x, y, _), = objs
        # Hand value: the lead where the trace has it at the stamp (at arrival it is 1.5 m on).
        assert x == pytest.approx(lead.x[k], abs=1e-6) and y == pytest.approx(lead.y[k], abs=1e-6)
        assert abs(x - lead.x[k + 10]) > 1.4


@pytest.mark.parametrize("perception", [
    "perception_noise 0.1 m",
    pytest.param("perception learned", marks=[pytest.mark.torch]),
])
def test_a_frames_detections_do_not_depend_on_when_it_arrives(perception):
    # Until 1 s the two runs are the same; the frame captured at 1 s reaches the stack at
    # once in one, 100 ms later in the other, when the ego has moved 1.5 m on: it must
    # report the same objects at the same places (it mapped them out through the pose at
    # its arrival, 1.5 m too far ahead).
    if "learned" in perception:
        pytest.importorskip("torch")
    on_time = detections(run(source(perception, "during [1 s, 2 s] drop lidar rate 0 %")))
    late = detections(run(source(perception, "during [1 s, 2 s] delay lidar by 100 ms")))
    assert on_time[1.0] and late[1.0] == on_time[1.0]


def test_a_frame_the_weather_thinned_keeps_what_was_true_at_its_capture():
    # Fog and rain hand the stack a new frame with fewer returns: it must keep the capture's
    # ego pose and ground truth (a thinned frame without them stopped the stack).
    src = source("perception_noise 0 m", "at 0.5 s drop lidar rate 0 %").replace(
        "  faults {", "  environment {\n    fog visibility 2 km\n  }\n  faults {")
    trace = run(src)
    lead = trace.actors["lead"]
    seen = {s: o for s, o in detections(trace).items() if o}
    assert len(seen) >= 20
    for stamp, objs in seen.items():
        k = int(np.searchsorted(trace.time, stamp - 1e-9))
        assert objs[0][0] == pytest.approx(lead.x[k], abs=1e-6)
