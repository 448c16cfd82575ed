"""The camera BEV perception node: rig, lift geometry, shipped weights, determinism, tensor fault sites."""

import math

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytestmark = pytest.mark.torch

from addt_dsl.runtime.sensors import CameraRig  # noqa: E402
from addt_dsl.stack.bev import PERCEPTIONS, BevStack  # noqa: E402
from addt_dsl.stack.bev_grid import CAMERA_BEV_SITES, CAMERA_BEV_TENSOR_SITES, DETECTOR_RIG, GRID, TENSOR_SITES  # noqa: E402
from addt_dsl.stack.camera_bev import WEIGHTS_PATH, CameraBevNet, CameraBevPerception  # noqa: E402
from addt_dsl.stack.camera_train import CameraSceneGenerator  # noqa: E402
from addt_dsl.stack.rig_lift import LIFT_HEIGHTS_M, lift_table  # noqa: E402


@pytest.fixture(scope="module")
def rig():
    return CameraRig("camera_rig", DETECTOR_RIG.settings())


@pytest.fixture(scope="module")
def scenes():
    """A given scene (a car ahead, a truck behind, a pedestrian on the left verge) and a
    random one of the training distribution from a held-out seed, rendered by the rig."""
    gen = CameraSceneGenerator(1_000_003)
    try:
        yield {"given": gen.render([("car", 15.0, 0.0, 0.0), ("truck", -22.0, 0.1, 0.0),
                                    ("pedestrian", 9.0, 5.0, 1.5)]),
               "random": gen.sample()}
    finally:
        gen.close()


@pytest.fixture(scope="module")
def scene(scenes):
    return scenes["random"]


def test_the_rig_renders_its_cameras_around_the_mount(rig, scenes):
    s = scenes["given"]
    assert s.images.shape == (6, 40, 128, 3) and s.images.dtype == np.uint8
    assert [round(math.degrees(e.yaw)) for e in rig.camera_extrinsics(rig.nominal)] == [0, 60, 120, 180, 240, 300]
    red, blue = np.array([0.8, 0.1, 0.1]), np.array([0.1, 0.2, 0.6])

    def share(k, colour):  # of camera k's pixels near a paint colour (lit or shaded)
        rgb = s.images[k].reshape(-1, 3) / 255.0
        cos = rgb @ colour / np.maximum(np.linalg.norm(rgb, axis=1) * np.linalg.norm(colour), 1e-9)
        return float(np.mean((cos > 0.97) & (rgb.max(axis=1) > 0.2)))

    assert share(0, red) > 0.01 and share(3, red) < 0.001  # the car: front camera only
    assert share(3, blue) > 0.01 and share(0, blue) < 0.001  # the truck: rear camera only
    assert s.hits.tolist()[0] > 50 and s.hits.tolist()[1] > 50


def test_lift_takes_each_cell_from_the_camera_that_sees_it_at_the_projected_pixel(rig):
    table = lift_table(rig.intrinsics, rig.camera_extrinsics(rig.nominal), rig.width, rig.height, stride=1)
    assert table.shape == (len(LIFT_HEIGHTS_M), GRID.nx, GRID.ny)
    pixels = rig.width * rig.height

    def cell(x, y):
        return int((x - GRID.x_min) / GRID.cell_m), int((y - GRID.y_min) / GRID.cell_m)

    # 20 m straight ahead at the mount's height: the front camera's centre.
    i, j = cell(20.0, 0.0)
    k = int(np.argmin(np.abs(np.array(LIFT_HEIGHTS_M) - 1.6)))
    index = table[k, i, j]
    assert index // pixels == 0
    row, col = divmod(index % pixels, rig.width)
    assert abs(col + 0.5 - rig.width / 2) <= 3 and abs(row + 0.5 - rig.height / 2) <= 3
    # Behind: the rear camera (yaw 180 deg); left and right of the mount: cameras 60/120 and 240/300 deg.
    assert table[k][cell(-20.0, 0.0)] // pixels == 3
    assert table[k][cell(0.0, 20.0)] // pixels in (1, 2)
    assert table[k][cell(0.0, -20.0)] // pixels in (4, 5)
    # Road-height points right beside the mount are below every camera's view: unseen.
    assert table[0][cell(0.4, 0.4)] == 6 * pixels


def test_layer_names_are_the_declared_fault_sites():
    convs = {n for n, m in CameraBevNet().named_modules() if isinstance(m, torch.nn.Conv2d)}
    assert convs == set(CAMERA_BEV_SITES)
    assert CameraBevPerception({}).fault_sites() == CAMERA_BEV_TENSOR_SITES
    assert set(CAMERA_BEV_TENSOR_SITES) <= BevStack.fault_sites({"perception": "camera_bev"})
    assert "perception.encoder.conv0" not in BevStack.fault_sites({"perception": "learned"})
    assert not set(CAMERA_BEV_TENSOR_SITES) & BevStack.fault_sites({"perception": "ground_truth"})
    assert set(CAMERA_BEV_TENSOR_SITES) | set(TENSOR_SITES) <= BevStack.fault_sites()


def test_weights_ship_small_and_are_trained_for_the_declared_rig():
    assert WEIGHTS_PATH.exists() and WEIGHTS_PATH.stat().st_size < 2 * 2**20
    meta = CameraBevPerception({}).meta
    assert meta["rig"] == DETECTOR_RIG.settings() and meta["heights"] == list(LIFT_HEIGHTS_M)
    keyword, expected = PERCEPTIONS["camera_bev"].expects
    assert keyword == "camera_rig" and expected == {k: meta["rig"][k] for k in expected}
    assert PERCEPTIONS["camera_bev"].needs_sensor == "camera_rig"


def test_detects_visible_road_users_near_where_they_are(rig, scene):
    node = CameraBevPerception({})
    found = node.detect(scene.images, node.geometry(rig))
    assert found.shape[1] == 7 and len(found) > 0
    near = [b for b, hits in zip(scene.boxes, scene.hits) if hits >= 40 and math.hypot(b[0], b[1]) < 25.0]
    assert near, "the held-out scene has road users close by"
    matched = sum(np.hypot(found[:, 0] - b[0], found[:, 1] - b[1]).min() < 2.0 for b in near)
    assert matched >= 0.7 * len(near)


def test_inference_is_deterministic_and_nodes_are_independent(rig, scene):
    a, b = CameraBevPerception({}), CameraBevPerception({})
    first = a.detect(scene.images, a.geometry(rig))
    assert np.array_equal(a.detect(scene.images, a.geometry(rig)), first)
    assert np.array_equal(b.detect(scene.images, b.geometry(rig)), first)


def test_weight_flip_is_persistent_and_flipping_back_restores_bit_for_bit(rig, scene):
    node = CameraBevPerception({})
    g = node.geometry(rig)
    clean = node.detect(scene.images, g)
    bias_index = node.model.layers()["head.center"].weight.numel()  # kernel first, then bias
    assert node.site_numel("perception.head.center") == bias_index + 1
    before, after = node.flip_weight_bits("perception.head.center", [bias_index], [31])
    assert after[0] == -before[0]
    flooded = node.detect(scene.images, g)
    assert len(flooded) > len(clean)
    assert len(node.detect(scene.images, g)) == len(flooded)
    node.flip_weight_bits("perception.head.center", [bias_index], [31])
    assert np.array_equal(node.detect(scene.images, g), clean)
    assert np.array_equal(CameraBevPerception({}).detect(scene.images, g), clean)


def test_activation_flips_last_one_inference(rig, scene):
    node = CameraBevPerception({})
    g = node.geometry(rig)
    clean = node.detect(scene.images, g)
    assert node.activation_shape("perception.head.center") == (1, 1, 76, 32)
    # A far, empty head cell's logit made positive: a ghost object for exactly one frame.
    node.flip_activation_bits("perception.head.center", [70 * 32 + 3], [31])
    ghost = node.detect(scene.images, g)
    site, (before, after) = node.last_activation_flips[0]
    assert site == "perception.head.center" and after[0] == -before[0] and before[0] < 0
    assert len(ghost) == len(clean) + 1
    assert np.array_equal(node.detect(scene.images, g), clean) and node.last_activation_flips == []


def test_an_encoder_flip_reaches_the_bev_cells_that_see_its_pixel(rig, scene):
    from addt_dsl.stack.camera_bev import images_tensor

    node = CameraBevPerception({})
    g = node.geometry(rig)
    assert node.activation_shape("perception.encoder.conv2") == (6, 8, 40, 128)  # the cameras are the batch
    x = images_tensor(scene.images)[None]
    with torch.inference_mode():
        clean = node.model.lift(x, g.table, g.position)
    # Feature 0 of the front camera's centre pixel, the exponent's top bit: a huge value
    # (cut by the ReLU if it was negative), lifted onto exactly the cells that see the pixel.
    index = 20 * 128 + 64
    flip = node.flip_activation_bits("perception.encoder.conv2", [index], [30])
    with torch.inference_mode():
        faulty = node.model.lift(x, g.table, g.position)
    (before,), (after,) = flip.fired
    assert abs(after) > 1e30 or math.isnan(after)
    changed = (faulty != clean).any(dim=1)[0]  # BEV cells whose lifted features changed
    cells = (g.table == index).any(dim=0)  # the cells that take that pixel
    assert cells.any()
    assert torch.equal(changed, cells) if not after < 0 else not changed.any()
    with pytest.raises(KeyError, match="unknown tensor site"):
        node.flip_weight_bits("perception.encoder.conv9", [0], [0])
    with pytest.raises(IndexError):
        node.flip_activation_bits("perception.encoder.conv0", [10**9], [0])


def test_compiler_checks_camera_bev_against_the_perception_table():
    from addt_dsl.compiler import compile_source

    def compile_with(sensor: str, fault: str = ""):
        return compile_source(f"""scenario s {{
  duration 1 s
  road r {{ line length 100 m }}
  ego car on r lane -1 at 10 m speed 5 m/s {{
    stack bev perception camera_bev
    {sensor}
  }}
  faults {{
    {fault}
  }}
}}""")

    assert compile_with("sensor camera_rig").ok
    assert compile_with("sensor camera_rig", "at 0.5 s bitflip perception.encoder.conv1 tensor weights").ok
    assert compile_with("sensor camera_rig", "drop camera_rig rate 5 %").ok
    missing = compile_with("sensor lidar")
    assert [d.code for d in missing.diagnostics] == ["E0103"] and "camera_rig" in missing.diagnostics[0].message


def test_training_is_reproducible_from_the_seed():
    from addt_dsl.stack.camera_train import train

    runs = [train(seed=11, scenes=6, epochs=1, batch=3, threads=1, lr=1e-3, log=lambda *_: None)[0]
            for _ in range(2)]
    other = train(seed=12, scenes=6, epochs=1, batch=3, threads=1, lr=1e-3, log=lambda *_: None)[0]
    a, b, c = (m.state_dict() for m in (*runs, other))
    assert all(torch.equal(a[k], b[k]) for k in a)
    assert not all(torch.equal(a[k], c[k]) for k in a)
