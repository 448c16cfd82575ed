"""Perception maps vehicle-frame boxes to the world in one place (`nodes.vehicle_to_world`):
checked by hand, through the detectors' box decoding, and by a scan of the stack's source."""

import math
import re
from pathlib import Path

import numpy as np
import pytest

from addt_dsl.stack.nodes import vehicle_to_world

STACK = Path(__file__).resolve().parents[3] / "addt_dsl" / "stack"


def test_vehicle_to_world_by_hand():
    # Ego at (10, 5) facing +y: a point 2 m ahead and 1 m to its left is at (9, 7).
    x, y = vehicle_to_world((10.0, 5.0, math.pi / 2, 3.0), 2.0, 1.0)
    assert (x, y) == (pytest.approx(9.0), pytest.approx(7.0))
    assert vehicle_to_world((1.0, 2.0, 0.0), 3.0, -4.0) == (4.0, -2.0)


def test_detector_boxes_map_through_it():
    pytest.importorskip("torch")
    from addt_dsl.stack.bev_grid import CLASSES
    from addt_dsl.stack.learned import boxes_to_world

    pose = (100.0, -3.0, 0.4, 20.0)
    boxes = np.array([[12.0, -1.5, 0.1, 4.6, 1.9, 0.9, 0], [30.0, 2.0, -0.2, 0.5, 0.5, 0.7, 2],
                      [5.0, 0.0, 0.0, 1.0, 1.0, 0.5, 99]])
    seen = []
    objs = boxes_to_world(boxes, pose, lambda site, v: seen.append(site) or v + (0.5 if site == "perception.x" else 0))
    assert seen == ["perception.x", "perception.y"] * 3  # each position passes the fault sites first
    for o, b in zip(objs, boxes):
        assert (o.x, o.y) == vehicle_to_world(pose, b[0] + 0.5, b[1])
        assert (o.heading, o.length, o.width, o.confidence) == (0.4 + b[2], b[3], b[4], b[5])
        assert math.isnan(o.vx) and math.isnan(o.vy)
    assert [o.kind for o in objs] == [CLASSES[0], CLASSES[2], ""]


def test_one_copy_of_the_transform_in_the_stack():
    # The rotation written out (`x + cos * px - sin * py`) lives in vehicle_to_world only.
    pattern = re.compile(r"\+\s*cos\w*\s*\*\s*p\w*\s*-\s*sin\w*\s*\*\s*p\w*")
    found = sorted(f"{p.name}:{n}" for p in STACK.glob("*.py")
                   for n, line in enumerate(p.read_text().splitlines(), 1) if pattern.search(line))
    assert len(found) == 1 and found[0].startswith("nodes.py:"), found
