"""The learned perception node: shipped weights, detections, tensor fault sites."""

import math

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from addt_dsl.stack.bev import BevStack  # noqa: E402
from addt_dsl.stack.bev_grid import LAYER_SITES, TENSOR_SITES  # noqa: E402
from addt_dsl.stack.learned import WEIGHTS_PATH, BevDetector, LearnedPerception  # noqa: E402
from addt_dsl.stack.synth import ScanGenerator  # noqa: E402


@pytest.fixture(scope="module")
def scans():
    gen = ScanGenerator(0)
    try:
        yield {
            "two": gen.scan([("car", 15.0, -0.2, 0.02), ("truck", -22.0, 3.5, 0.0)]),
            "empty": gen.scan([]),
        }
    finally:
        gen.close()


def test_weights_ship_small_and_match_the_architecture():
    assert WEIGHTS_PATH.exists()
    assert WEIGHTS_PATH.stat().st_size < 4 * 2**20
    node = LearnedPerception({})
    assert node.meta["grid"]["cell_m"] == 0.8


def test_layer_names_are_the_declared_fault_sites():
    model = BevDetector()
    convs = {n for n, m in model.named_modules() if isinstance(m, torch.nn.Conv2d)}
    assert convs == set(LAYER_SITES)
    assert LearnedPerception({}).fault_sites() == TENSOR_SITES
    assert set(TENSOR_SITES) <= BevStack.fault_sites({"perception": "learned"})
    assert not set(TENSOR_SITES) & BevStack.fault_sites({"perception": "ground_truth"})
    assert set(TENSOR_SITES) <= BevStack.fault_sites()  # compile-time check: any perception


def test_detects_a_car_and_a_truck_where_they_are(scans):
    node = LearnedPerception({})
    s = scans["two"]
    found = node.detect(s.points, s.sensor_xy)
    assert len(found) == 2
    for gt in s.boxes:
        k = int(np.argmin(np.hypot(found[:, 0] - gt[0], found[:, 1] - gt[1])))
        x, y, heading, length, width, conf = found[k]
        assert math.hypot(x - gt[0], y - gt[1]) < 0.6
        assert abs(length - gt[3]) < 1.0 and conf > node.threshold
    assert len(node.detect(scans["empty"].points, scans["empty"].sensor_xy)) == 0


def test_weight_flip_is_persistent_and_flipping_back_restores_bit_for_bit(scans):
    node = LearnedPerception({})
    s = scans["two"]
    clean = node.detect(s.points, s.sensor_xy)
    layer = node.model.layers()["head.center"]
    bias_index = layer.weight.numel()  # kernel first, then bias
    assert node.site_numel("perception.head.center") == bias_index + 1
    before, after = node.flip_weight_bits("perception.head.center", [bias_index], [31])  # sign of the bias
    assert after[0] == -before[0]
    flooded = node.detect(s.points, s.sensor_xy)
    assert len(flooded) > len(clean)  # a positive bias puts peaks everywhere
    assert len(node.detect(s.points, s.sensor_xy)) == len(flooded)  # still faulty next frame
    node.flip_weight_bits("perception.head.center", [bias_index], [31])
    assert np.array_equal(node.detect(s.points, s.sensor_xy), clean)
    # A fresh node is unaffected by another node's faults.
    assert np.array_equal(LearnedPerception({}).detect(s.points, s.sensor_xy), clean)


def test_activation_flip_lasts_one_inference(scans):
    node = LearnedPerception({})
    s = scans["two"]
    clean = node.detect(s.points, s.sensor_xy)
    shape = node.activation_shape("perception.head.center")
    assert shape == (1, 1, 76, 32)
    # Make a far, empty cell's logit positive: a ghost object for exactly one frame.
    index = 70 * 32 + 3
    node.flip_activation_bits("perception.head.center", [index], [31])
    ghost = node.detect(s.points, s.sensor_xy)
    assert len(ghost) == len(clean) + 1
    site, (before, after) = node.last_activation_flips[0]
    assert site == "perception.head.center" and after[0] == -before[0] and before[0] < 0
    assert np.array_equal(node.detect(s.points, s.sensor_xy), clean)
    assert node.last_activation_flips == []


def test_fault_site_errors_are_clear():
    node = LearnedPerception({})
    with pytest.raises(KeyError, match="unknown tensor site"):
        node.flip_weight_bits("perception.backbone.9", [0], [0])
    with pytest.raises(IndexError):
        node.flip_activation_bits("perception.backbone.conv0", [10**9], [0])
    with pytest.raises(ValueError):
        node.site_numel("perception.backbone.conv0", "gradients")


@pytest.mark.parametrize("site", TENSOR_SITES)
def test_every_tensor_site_is_a_valid_fault_target_with_learned_perception_only(site):
    from pathlib import Path

    from addt_dsl.compiler import compile_source

    source = (Path(__file__).resolve().parents[3] / "examples" / "overtake.addt").read_text()
    stack = "stack bev cruise_speed 25 m/s"
    fault = "drop lidar rate drop_rate"
    assert stack in source and fault in source
    text = source.replace(fault, f"{fault}\n    at 5 s bitflip {site} tensor weights")
    learned = compile_source(text.replace(stack, "stack bev perception learned cruise_speed 25 m/s"))
    assert learned.ok, learned.diagnostics
    ground_truth = compile_source(text)
    assert not ground_truth.ok
    assert any("cannot target" in d.message for d in ground_truth.diagnostics)
