"""Sensors: camera by pybullet's TinyRenderer, IMU and GNSS with noise and lever arms,
extrinsics, timestamps; road visuals are built only when a camera is fitted."""

import math

import cv2
import numpy as np
import pytest

from addt_dsl.compiler import compile_source
from addt_dsl.runtime.state import RunState
from addt_dsl.runtime.sensors import Extrinsics, _look_at, _perspective, rotation, _sensor_world_pose
from addt_dsl.sweep import expand

SCENARIO = """
scenario sensors {{
  duration 1 s
  road r {{
    line length 300 m
    lanes right 2 width 3.5 m
  }}
  ego car on r lane -1 at 20 m speed 10 m/s {{
    stack bev
    {sensors}
  }}
  agent lead car on r lane -1 at 50 m speed 10 m/s {{
    behavior cruise speed 10 m/s
  }}
}}
"""


def make_run(sensors: str) -> RunState:
    result = compile_source(SCENARIO.format(sensors=sensors))
    assert result.plan is not None, result.diagnostics
    return RunState(expand(result.plan).specs[0])


def pose_agents(run: RunState) -> None:
    for a in run.agents:
        x, y, h = run.agent_roads[a.name].pose(a.s, a.t)
        run.physics.set_pose(a.name, x, y, 0.75, h)


@pytest.fixture(scope="module")
def camera_run():
    run = make_run("sensor camera rate 10 Hz width 160 height 120 fov 60 deg")
    pose_agents(run)
    yield run
    run.physics.close()


def test_view_and_projection_matrices_match_pybullet(camera_run):
    p = camera_run.physics.p
    ext = Extrinsics(x=1.2, y=0.3, z=1.5, roll=0.0, pitch=0.1, yaw=-0.2)
    origin, rot = _sensor_world_pose((5.0, -2.0, 1.0, 0.7, 0.05), ext)
    ours = _look_at(origin, rot)
    ref = p.computeViewMatrix(origin.tolist(), (origin + rot[:, 0]).tolist(), rot[:, 2].tolist())
    assert np.allclose(ours, ref, atol=1e-6)
    assert np.allclose(_perspective(math.radians(50.0), 4 / 3, 0.1, 150.0),
                       p.computeProjectionMatrixFOV(50.0, 4 / 3, 0.1, 150.0), atol=1e-6)


def test_camera_sees_the_road_its_markings_and_the_car_ahead(camera_run):
    run = camera_run
    assert run.physics.visual and run.scene.visual_triangles > 0
    frame = run.sensors["camera"].capture(run, 0.25)
    assert frame.stamp_s == 0.25
    img, depth, seg = frame.data["image"], frame.data["depth"], frame.data["segmentation"]
    assert img.shape == (120, 160, 3) and img.dtype == np.uint8 and img.flags["C_CONTIGUOUS"]
    lead_id = run.physics.bodies["lead"]
    assert seg[60, 80] == lead_id  # straight ahead
    # Camera 1 m ahead of the ego centre (s = 21 m); the lead's rear face at 50 - 2.3 m.
    assert depth[60, 80] == pytest.approx(50.0 - 2.3 - 21.0, rel=0.03)
    # The lower image is road surface; markings are bright pixels on both sides.
    assert np.isin(seg[110:, :], list(run.physics.ground_ids)).all()
    gray = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
    bright = gray[70:, :] > 150
    assert bright[:, :70].any() and bright[:, 90:].any()
    assert cv2.Canny(gray, 50, 150).sum() > 0
    asphalt = img[115, 80].astype(int)
    assert asphalt.max() < 90 and abs(asphalt[0] - asphalt[2]) < 15  # dark grey


def test_terrain_reaches_the_horizon_far_from_the_origin(camera_run):
    # pybullet's plane is drawn only ~130 m around its origin; the terrain mesh covers
    # the whole network, so no sky shows below the horizon anywhere on the road.
    run = camera_run
    x0 = run.ego.x
    run.ego.x = 290.0
    try:
        frame = run.sensors["camera"].capture(run, 0.0)
    finally:
        run.ego.x = x0
    seg = frame.data["segmentation"]
    assert (seg[64:, :] != -1).all()
    assert run.physics.ground not in np.unique(seg)  # the plane itself is hidden


def test_camera_extrinsics_turn_the_view(camera_run):
    run = camera_run
    cam = run.sensors["camera"]
    cam.actual = cam.nominal.shifted(yaw=math.radians(90.0))
    try:
        seg = cam.capture(run, 0.0).data["segmentation"]
    finally:
        cam.actual = cam.nominal
    assert run.physics.bodies["lead"] not in np.unique(seg)


def test_camera_intrinsics_are_a_pinhole_model(camera_run):
    cam = camera_run.sensors["camera"]
    k = cam.intrinsics
    assert k[0, 0] == pytest.approx(80.0 / math.tan(math.radians(30.0)))
    assert k[0, 0] == pytest.approx(k[1, 1])  # square pixels
    assert (k[0, 2], k[1, 2]) == (80.0, 60.0)


def test_no_visual_geometry_without_a_camera():
    run = make_run("sensor lidar rate 10 Hz")
    try:
        assert not run.physics.visual
        assert run.scene.bodies == 0 and run.scene.visual_triangles == 0
    finally:
        run.physics.close()


def test_imu_noise_bias_and_gravity():
    run = make_run("sensor imu rate 100 Hz accel_noise 0.1 m/s^2 gyro_noise 0.01 rad/s accel_bias 0.2 m/s^2")
    try:
        imu = run.sensors["imu"]
        assert imu.period_s == pytest.approx(0.01)
        frames = [imu.capture(run, k * 0.01) for k in range(400)]
        acc = np.array([f.data["accel"] for f in frames])
        gyro = np.array([f.data["gyro"] for f in frames])
        assert frames[7].stamp_s == pytest.approx(0.07)
        assert acc.mean(axis=0) == pytest.approx([0.2, 0.2, 9.81 + 0.2], abs=0.03)
        assert acc.std(axis=0) == pytest.approx([0.1] * 3, rel=0.15)
        assert gyro.std(axis=0) == pytest.approx([0.01] * 3, rel=0.15)
    finally:
        run.physics.close()


def test_imu_reads_cornering_lever_arm_and_mount_rotation():
    run = make_run("sensor imu accel_noise 0 m/s^2 gyro_noise 0 rad/s x 2 m yaw 90 deg")
    try:
        e = run.ego
        e.vx, e.yaw_rate, e.ay, e.ax_specific, e.yaw_acc = 20.0, 0.2, 4.0, 0.5, 0.0
        data = run.sensors["imu"].capture(run, 0.0).data
        # Vehicle frame at the mount: f_x = 0.5 - r^2 * 2 m, f_y = 4; rotated by the mount
        # yaw of 90 deg the sensor's x axis points left.
        f_vehicle = np.array([0.5 - 0.2 ** 2 * 2.0, 4.0, 9.81])
        assert data["accel"] == pytest.approx(rotation(0.0, 0.0, math.pi / 2).T @ f_vehicle, abs=1e-9)
        assert data["accel"][0] == pytest.approx(4.0)
        assert data["gyro"] == pytest.approx([0.0, 0.0, 0.2], abs=1e-12)
    finally:
        run.physics.close()


def test_gnss_reports_the_antenna_position():
    run = make_run("sensor gnss noise 0 m x 2 m y 0.5 m z 1.5 m")
    try:
        run.ego.heading = math.pi / 2
        data = run.sensors["gnss"].capture(run, 0.0).data
        assert (data["x"], data["y"], data["z"]) == pytest.approx((run.ego.x - 0.5, run.ego.y + 2.0, 1.5))
    finally:
        run.physics.close()


def test_sensor_mount_follows_the_road_grade():
    ext = Extrinsics(x=1.0, y=0.0, z=1.0)
    origin, rot = _sensor_world_pose((0.0, 0.0, 10.0, 0.0, math.atan(0.1)), ext)
    assert rot[:, 0] == pytest.approx([math.cos(math.atan(0.1)), 0.0, math.sin(math.atan(0.1))])
    assert origin[2] == pytest.approx(10.0 + math.sin(math.atan(0.1)) + math.cos(math.atan(0.1)))
    # A positive mount pitch looks down.
    _, down = _sensor_world_pose((0.0, 0.0, 0.0, 0.0, 0.0), Extrinsics(pitch=0.2))
    assert down[2, 0] < 0.0


def test_lidar_frame_is_stamped_and_sees_the_lead():
    run = make_run("sensor lidar rate 10 Hz rays 720 range 80 m")
    try:
        pose_agents(run)
        run.body_actor = {}
        frame = run.sensors["lidar"].capture(run, 0.3)
        assert frame.stamp_s == 0.3
        lead = run.physics.bodies["lead"]
        pts = frame.data["points"][frame.data["hit_body"] == lead]
        assert len(pts) > 5
        # Sensor 1 m ahead of the ego centre: the rear face 26.7 m ahead.
        assert pts[:, 0].min() == pytest.approx(26.7, abs=0.05)
    finally:
        run.physics.close()


def test_box_separation_equals_the_corner_projection_reference():
    from hypothesis import given, settings
    from hypothesis import strategies as st

    from addt_dsl.runtime.world import box_corners, box_separation

    def reference(a, b):
        ca, cb = box_corners(*a), box_corners(*b)
        best = -math.inf
        for h in (a[2], b[2]):
            for axis in ((math.cos(h), math.sin(h)), (-math.sin(h), math.cos(h))):
                pa, pb = ca @ axis, cb @ axis
                best = max(best, pb.min() - pa.max(), pa.min() - pb.max())
        return best

    box = st.tuples(st.floats(-20, 20), st.floats(-20, 20), st.floats(-4, 4), st.floats(0.3, 15), st.floats(0.3, 3))

    @settings(max_examples=200, deadline=None)
    @given(box, box)
    def check(a, b):
        assert box_separation(a, b) == pytest.approx(reference(a, b), abs=1e-9)

    check()
