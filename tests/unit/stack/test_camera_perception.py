"""The camera colour detector on synthetic frames (no renderer): geometry, segmentation,
and what image faults do to it; the perception mode table and its compile-time check."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from addt_dsl.compiler import compile_source
from addt_dsl.runtime.sensors import Camera, Frame
from addt_dsl.vehicles import VEHICLES
from addt_dsl.stack.bev import PERCEPTIONS, BevStack
from addt_dsl.stack.camera_perception import CLASS_SIZE_M, CameraPerception, ColourDetector

W, H = 160, 120
CAMERA = Camera("camera", {"width": W, "height": H, "fov": math.radians(60.0)})
ASPHALT, SKY = (56, 56, 61), (255, 255, 255)
SKY_DEPTH = 150.0


def scene(boxes):
    """An RGB-D frame: sky above the horizon, road below, and camera-facing boxes
    [(class, forward [m], left [m], width [m], height [m], shade)] drawn far to near."""
    img = np.empty((H, W, 3), np.uint8)
    img[: H // 2] = SKY
    img[H // 2:] = ASPHALT
    depth = np.full((H, W), SKY_DEPTH, np.float32)
    rows = np.arange(H)[:, None] + 0.5
    below = rows > H / 2
    fy = CAMERA.intrinsics[1, 1]
    depth[:] = np.where(below, np.minimum(SKY_DEPTH, CAMERA.settings["z"] * fy / np.maximum(rows - H / 2, 1e-3)),
                        SKY_DEPTH)
    fx, cx, cy = CAMERA.intrinsics[0, 0], CAMERA.intrinsics[0, 2], CAMERA.intrinsics[1, 2]
    z_cam = CAMERA.settings["z"]
    for name, fwd, left, width, height, shade in sorted(boxes, key=lambda b: -b[1]):
        u0, u1 = cx - (left + width / 2) * fx / fwd, cx - (left - width / 2) * fx / fwd
        v0, v1 = cy - (height - z_cam) * fy / fwd, cy + z_cam * fy / fwd
        c0, c1, r0, r1 = (int(round(max(0, u0))), int(round(min(W, u1))),
                          int(round(max(0, v0))), int(round(min(H, v1))))
        rgb = [round(255 * shade * c) for c in VEHICLES[name].rgba[:3]]
        img[r0:r1, c0:c1] = rgb
        depth[r0:r1, c0:c1] = fwd
    return img, depth


def detect(img, depth):
    return ColourDetector().detect(img, depth, CAMERA.intrinsics)


def face_to_vehicle(face):
    return face[0] + CAMERA.nominal.x, face[1] + CAMERA.nominal.y


@settings(max_examples=40, deadline=None)
# Up to 60 m: a car seen from behind (1.9 x 1.5 m) is about 4 x 3 px at 65 m, and the 3 x 3
# median filter removes smaller blobs (found out to 66 m; a truck's rear beyond 85 m).
@given(st.floats(8.0, 60.0), st.floats(-4.0, 4.0), st.floats(0.45, 1.0), st.sampled_from(["car", "truck"]))
def test_a_vehicle_is_found_where_it_is_whatever_its_shading(fwd, left, shade, name):
    size = {"car": (1.9, 1.5), "truck": (2.5, 3.5)}[name]
    # Wholly inside the 60° field of view (a vehicle cut by the image border is seen only
    # in part, and the centre of its visible part is not its bearing).
    assume(abs(left) + size[0] / 2 < fwd * math.tan(math.radians(30.0)) - 0.2)
    img, depth = scene([(name, fwd, left, *size, shade)])
    (found,) = detect(img, depth)
    cls, face, _ = found
    assert cls == name
    assert face[0] == pytest.approx(fwd, abs=1e-3)  # the depth of the face
    px = fwd / CAMERA.intrinsics[0, 0]  # one pixel at that range [m]
    assert face[1] == pytest.approx(left, abs=px)  # bearing within a pixel


def test_road_sky_markings_and_verge_are_not_vehicles():
    img, depth = scene([])
    img[100:104, 20:140] = (242, 242, 242)  # a marking
    img[60:70, :30] = (84, 115, 69)  # verge
    img[70:80, 130:] = (140, 77, 71)  # a biking lane, reddish but unsaturated
    assert detect(img, depth) == []


def test_two_vehicles_of_different_colours_are_two_objects():
    img, depth = scene([("car", 30.0, 0.0, 1.9, 1.5, 0.8), ("truck", 45.0, -3.5, 2.5, 3.5, 0.8)])
    found = sorted((c, round(f[0])) for c, f, _ in detect(img, depth))
    assert found == [("car", 30), ("truck", 45)]


def test_occluding_the_vehicle_removes_the_detection_and_noise_does_not_invent_one():
    from tests.unit.runtime.faults.faultkit import one

    img, depth = scene([("car", 25.0, 0.0, 1.9, 1.5, 0.8)])
    assert len(detect(img, depth)) == 1
    occlude, _ = one("occlude", target="camera", fraction=1.0)
    frame, _ = occlude.on_frame(Frame("camera", 0.0, {"image": img}), 0.0)
    assert detect(frame.data["image"], depth) == []
    noise, _ = one("image_noise", target="camera", sigma=15.0, salt=0.01)
    noisy, _ = noise.on_frame(Frame("camera", 0.0, {"image": img}), 0.0)
    assert [c for c, _, _ in detect(noisy.data["image"], depth)] == ["car"]


def test_blur_loses_a_distant_vehicle_first():
    from tests.unit.runtime.faults.faultkit import one

    img, depth = scene([("car", 12.0, -2.0, 1.9, 1.5, 0.8), ("car", 70.0, 3.5, 1.9, 1.5, 0.8)])
    assert sorted(round(f[0]) for _, f, _ in detect(img, depth)) == [12, 70]
    blur, _ = one("blur", target="camera", sigma=3.0)
    blurred, _ = blur.on_frame(Frame("camera", 0.0, {"image": img}), 0.0)
    assert [round(f[0]) for _, f, _ in detect(blurred.data["image"], depth)] == [12]


def test_the_node_places_the_box_centre_in_world_coordinates_through_the_nominal_extrinsics():
    img, depth = scene([("car", 20.0, 1.0, 1.9, 1.5, 0.9)])
    frame = Frame("camera", 0.0, {"image": img, "depth": depth, "intrinsics": CAMERA.intrinsics})
    node = CameraPerception({})
    assert node.accepts(frame) and not node.accepts(Frame("lidar", 0.0, {"points": [], "hit_body": []}))
    ego = (100.0, 50.0, math.pi / 2, 10.0)  # facing +y
    (obj,) = node.run(frame, CAMERA, ego, lambda site, v: v)
    x_v = 20.0 + CAMERA.nominal.x + CLASS_SIZE_M["car"][0] / 2  # face + half a car
    assert (obj.x, obj.y) == pytest.approx((100.0 - 1.0, 50.0 + x_v), abs=0.1)
    assert obj.heading == ego[2] and math.isnan(obj.vx)
    # A fault site corrupts what the node hands on, as for the lidar perceptions.
    (moved,) = node.run(frame, CAMERA, ego, lambda site, v: v + 5.0 if site == "perception.x" else v)
    assert moved.y == pytest.approx(obj.y + 5.0)


def test_perception_modes_come_from_one_table_the_compiler_checks():
    spec = next(p for p in BevStack.params if p.name == "perception")
    assert spec.choices == tuple(PERCEPTIONS) and "camera" in spec.choices
    assert BevStack.required_sensors({"perception": "camera"}) == {"camera"}
    assert BevStack.required_sensors({}) == set()

    def compile_with(stack: str, sensors: str):
        return compile_source(f"""scenario s {{
  duration 1 s
  road r {{ line length 100 m }}
  ego car on r lane -1 at 10 m speed 5 m/s {{
    stack bev {stack}
    {sensors}
  }}
}}""")

    assert compile_with("perception camera", "sensor camera").ok
    missing = compile_with("perception camera", "sensor lidar")
    assert [d.code for d in missing.diagnostics] == ["E0103"] and "camera sensor" in missing.diagnostics[0].message
    unknown = compile_with("perception sonar", "sensor lidar")
    assert not unknown.ok and "camera" in str(unknown.diagnostics[0])
