"""The OSI message mapping (addt_dsl.stack.osi_mapping) against hand-computed values."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

pytest.importorskip("osi3", reason="the `osi` extra (osi-python) is not installed")

from osi3.osi_motionrequest_pb2 import MotionRequest  # noqa: E402
from osi3.osi_object_pb2 import MovingObject, StationaryObject  # noqa: E402
from osi3.osi_sensorview_pb2 import SensorView  # noqa: E402
from osi3.osi_trafficlight_pb2 import TrafficLight  # noqa: E402
from osi3.osi_trafficupdate_pb2 import TrafficUpdate  # noqa: E402
from osi3.osi_lane_pb2 import LaneBoundary  # noqa: E402

from addt_dsl.plan import LIGHT_STATES, RoadPlan, SegmentPlan  # noqa: E402
from addt_dsl.road.roadspec import build_network  # noqa: E402
from addt_dsl.stack import osi_mapping as M  # noqa: E402

HOST = M.ObjectState(1, "ego", 10.0, 2.0, 0.75, 0.5, 3.0, 4.0, 4.6, 1.9, 1.5, ax=0.6, ay=0.8, yaw_rate=0.1,
                     pitch_nose_up=0.1)
TRUCK = M.ObjectState(2, "truck", 40.0, -1.75, 1.75, 0.0, 15.0, 0.0, 12.0, 2.5, 3.5)
WALKER = M.ObjectState(3, "pedestrian", 30.0, 5.0, 0.9, math.pi / 2, 0.0, 1.2, 0.5, 0.5, 1.8)
BOX = M.ObjectState(4, "obstacle", 60.0, -1.75, 0.5, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0)
LIGHT = M.LightState(0, "tl", 80.0, -1.75, 0.0, 0.0, LIGHT_STATES["red"])


def test_timestamps_are_seconds_and_nanoseconds():
    sv = SensorView()
    M.set_timestamp(sv.timestamp, 1.25)
    assert (sv.timestamp.seconds, sv.timestamp.nanos) == (1, 250_000_000)
    M.set_timestamp(sv.timestamp, 2.9999999999999)  # rounds up to the next whole second
    assert (sv.timestamp.seconds, sv.timestamp.nanos) == (3, 0)
    M.set_timestamp(sv.timestamp, 0.01 * 7)
    assert (sv.timestamp.seconds, sv.timestamp.nanos) == (0, 70_000_000)
    assert M.seconds(sv.timestamp) == pytest.approx(0.07, abs=1e-12)


def test_a_view_before_the_first_frame_has_no_stamp():
    # The host alone, before the sensor's first frame: its odometry stamped now, but no view
    # stamp (a stamp 0 s would be taken for the late first frame's, stamped 0 s too).
    sv = SensorView.FromString(M.sensor_view(M.WorldView(0.0, HOST), HOST, 0.02, sensed=False).SerializeToString())
    assert not sv.HasField("timestamp") and not sv.global_ground_truth.HasField("timestamp")
    assert M.seconds(sv.host_vehicle_data.timestamp) == pytest.approx(0.02, abs=1e-12)
    assert [o.id.value for o in sv.global_ground_truth.moving_object] == [1]
    stamped = SensorView.FromString(M.sensor_view(M.WorldView(0.0, HOST), HOST, 0.02).SerializeToString())
    assert stamped.HasField("timestamp") and stamped.global_ground_truth.HasField("timestamp")


def test_ground_truth_objects_frames_and_classes():
    view = M.WorldView(3.5, HOST, [TRUCK, WALKER, BOX], [LIGHT])
    sv = SensorView.FromString(M.sensor_view(view, HOST, 3.6).SerializeToString())  # as the peer reads it
    gt = sv.global_ground_truth
    assert (sv.timestamp.seconds, sv.timestamp.nanos) == (3, 500_000_000)
    assert (sv.host_vehicle_data.timestamp.seconds, sv.host_vehicle_data.timestamp.nanos) == (3, 600_000_000)
    assert gt.host_vehicle_id.value == sv.host_vehicle_id.value == 1
    assert (gt.version.version_major, gt.version.version_minor) == (3, 8)
    assert [o.id.value for o in gt.moving_object] == [1, 2, 3]
    host = gt.moving_object[0].base
    assert (host.position.x, host.position.y, host.position.z) == (10.0, 2.0, 0.75)
    assert (host.dimension.length, host.dimension.width, host.dimension.height) == (4.6, 1.9, 1.5)
    assert host.orientation.yaw == 0.5
    assert host.orientation.pitch == -0.1  # nose up is a negative rotation about OSI's y (left)
    assert (host.velocity.x, host.velocity.y, host.acceleration.x, host.acceleration.y) == (3.0, 4.0, 0.6, 0.8)
    assert host.orientation_rate.yaw == 0.1
    truck, walker = gt.moving_object[1], gt.moving_object[2]
    assert truck.type == MovingObject.TYPE_VEHICLE
    assert truck.vehicle_classification.type == MovingObject.VehicleClassification.TYPE_HEAVY_TRUCK
    assert walker.type == MovingObject.TYPE_PEDESTRIAN
    assert [M.object_kind(o) for o in gt.moving_object] == ["car", "truck", "pedestrian"]
    assert len(gt.stationary_object) == 1
    box = gt.stationary_object[0]
    assert box.id.value == 4 and box.classification.type == StationaryObject.Classification.TYPE_OTHER
    assert (box.base.position.x, box.base.position.z) == (60.0, 0.5)
    # One TrafficLight per bulb: red lit, yellow and green off.
    bulbs = {tl.id.value: (tl.classification.color, tl.classification.mode) for tl in gt.traffic_light}
    C = TrafficLight.Classification
    assert bulbs == {M.LIGHT_ID_BASE: (C.COLOR_RED, C.MODE_CONSTANT),
                     M.LIGHT_ID_BASE + 1: (C.COLOR_YELLOW, C.MODE_OFF),
                     M.LIGHT_ID_BASE + 2: (C.COLOR_GREEN, C.MODE_OFF)}
    # The host's own state now: host_vehicle_data.location.
    assert sv.host_vehicle_data.location.position.x == 10.0


def test_traffic_update_sets_the_host():
    tu = TrafficUpdate()
    M.set_timestamp(tu.timestamp, 1.01)
    u = tu.update.add()
    u.id.value = 1
    b = u.base
    b.position.x, b.position.y, b.orientation.yaw = 5.0, -1.0, 0.25
    b.velocity.x, b.velocity.y, b.acceleration.x = 9.0, 1.0, -2.0
    host = M.host_from_traffic_update(TrafficUpdate.FromString(tu.SerializeToString()))
    assert host == M.HostState(1.01, 5.0, -1.0, 0.25, 9.0, 1.0, -2.0, 0.0, 0.0)
    other = TrafficUpdate()
    other.CopyFrom(tu)
    other.update[0].id.value = 7
    with pytest.raises(M.MappingError, match="0 updates for the host"):
        M.host_from_traffic_update(other)
    bad = TrafficUpdate()
    bad.CopyFrom(tu)
    bad.update[0].base.position.x = math.nan
    with pytest.raises(M.MappingError, match="not finite"):
        M.host_from_traffic_update(bad)


def _desired_state(t, x, y, yaw, v, a) -> MotionRequest:
    mr = MotionRequest()
    mr.motion_request_type = MotionRequest.MOTION_REQUEST_TYPE_DESIRED_STATE
    d = mr.desired_state
    M.set_timestamp(d.timestamp, t)
    d.position.x, d.position.y, d.orientation.yaw = x, y, yaw
    d.velocity.x, d.velocity.y = v * math.cos(yaw), v * math.sin(yaw)
    d.acceleration.x, d.acceleration.y = a * math.cos(yaw), a * math.sin(yaw)
    return mr


def test_follow_pure_pursuit_by_hand():
    # Target 10 m ahead, 1 m left: curvature 2 * 1 / (10^2 + 1^2) = 0.0198020 1/m;
    # steer atan(2.7 * 0.0198020) = atan(0.0534653) = 0.0534144 rad.
    targets = M.targets_from_motion_request(_desired_state(0.5, 10.0, 1.0, 0.2, 20.0, 0.0))
    steer, accel = M.follow(targets, (0.0, 0.0, 0.0, 20.0), 0.0, 2.7)
    assert steer == pytest.approx(0.0534144, abs=1e-7)
    assert accel == pytest.approx(0.0, abs=1e-12)  # 20 m/s asked, 20 m/s reached with 0 m/s^2
    # Slower than asked: 0.5 * (20 - 18) = 1 m/s^2 on top of the request's 0.
    assert M.follow(targets, (0.0, 0.0, 0.0, 18.0), 0.0, 2.7)[1] == pytest.approx(1.0)


def test_follow_inverts_a_kinematic_rollout():
    """A desired state on the arc a bicycle drives under (steer, accel) gives them back."""
    L, steer, accel, v, h = 2.7, 0.05, 1.0, 20.0, 0.5
    k = math.tan(steer) / L
    arc = v * h + 0.5 * accel * h * h
    heading0 = 0.3
    lx, ly = math.sin(k * arc) / k, (1 - math.cos(k * arc)) / k
    c, s = math.cos(heading0), math.sin(heading0)
    x, y = 100.0 + c * lx - s * ly, 50.0 + s * lx + c * ly
    mr = _desired_state(2.0 + h, x, y, heading0 + k * arc, v + accel * h, accel)
    got = M.follow(M.targets_from_motion_request(mr), (100.0, 50.0, heading0, v), 2.0, L)
    assert got == pytest.approx((steer, accel), abs=1e-9)


def test_follow_a_stop_within_the_horizon():
    """Full braking (-7.848 m/s^2) from 3 m/s stops in 0.38 s, inside the 0.5 s horizon: the
    desired state stands 3^2 / (2 * 7.848) = 0.573 m ahead at 0 m/s, and the command is the
    braking itself, not braking eased by the speed the vehicle would have had in reverse."""
    mr = _desired_state(10.5, 9 / (2 * 7.848), 0.0, 0.0, 0.0, -7.848)
    steer, accel = M.follow(M.targets_from_motion_request(mr), (0.0, 0.0, 0.0, 3.0), 10.0, 2.7)
    assert accel == pytest.approx(-7.848, abs=1e-9) and steer == pytest.approx(0.0, abs=1e-12)


def test_trajectory_is_pursued_ahead_in_time():
    mr = MotionRequest()
    mr.motion_request_type = MotionRequest.MOTION_REQUEST_TYPE_TRAJECTORY
    for k in range(6):  # straight along +x at 10 m/s, points every 0.2 s
        p = mr.desired_trajectory.trajectory_point.add()
        M.set_timestamp(p.timestamp, 0.2 * k)
        p.position.x, p.position.y = 2.0 * k, 0.0
    targets = M.targets_from_motion_request(mr)
    target = M._trajectory_target(targets, 0.0)
    assert target.x == pytest.approx(3.0) and target.speed == pytest.approx(10.0)  # at 0.3 s
    steer, accel = M.follow(targets, (0.0, 0.5, 0.0, 10.0), 0.0, 2.7)
    # 0.5 m left of the line: steer right, toward (3, 0): 2 * -0.5 / (9 + 0.25).
    assert steer == pytest.approx(math.atan(2.7 * 2 * -0.5 / 9.25))
    assert accel == pytest.approx(0.0, abs=1e-9)


def test_bad_motion_requests_are_refused():
    with pytest.raises(M.MappingError, match="lacks timestamp"):  # type 0 is a desired state
        M.targets_from_motion_request(MotionRequest())
    # An unknown type on the wire (7) parses as the default, a desired state, which lacks its fields.
    with pytest.raises(M.MappingError, match="lacks timestamp"):
        M.targets_from_motion_request(MotionRequest.FromString(bytes([3 << 3, 7])))
    mr = _desired_state(1.0, math.inf, 0.0, 0.0, 10.0, 0.0)
    with pytest.raises(M.MappingError, match="not finite"):
        M.targets_from_motion_request(mr)
    mr = MotionRequest()
    mr.motion_request_type = MotionRequest.MOTION_REQUEST_TYPE_TRAJECTORY
    with pytest.raises(M.MappingError, match="no points"):
        M.targets_from_motion_request(mr)


def test_lanes_of_a_straight_two_lane_road():
    plan = RoadPlan(name="r", source="inline", segments=[SegmentPlan(kind="line", length_m=100.0)], right_lanes=2)
    network = build_network([plan])["r"]
    road = network.road(next(iter(network.roads)))
    lanes, boundaries = M.sample_lanes([road])
    base = M.LANE_ID_BASE + 50
    assert [ln.id for ln in lanes] == [base - 1, base - 2]
    by_id = {b.id: b for b in boundaries}
    assert sorted(by_id) == [base - 2, base - 1, base]
    # Centre line at t = 0 (a one-way road's left edge: solid), lane -1's outer border at
    # t = -3.5 (between lanes of one direction: dashed), lane -2's at -7 (the edge: solid).
    assert [by_id[base + k].points[0][1] for k in (0, -1, -2)] == pytest.approx([0.0, -3.5, -7.0])
    assert [by_id[base + k].solid for k in (0, -1, -2)] == [True, False, True]
    lane1 = lanes[0]
    assert lane1.centerline[0][:2] == pytest.approx((0.0, -1.75))
    assert lane1.centerline[-1][:2] == pytest.approx((100.0, -1.75))
    assert len(lane1.centerline) == 21  # every 5 m over 100 m
    assert (lane1.left_boundary, lane1.right_boundary) == (base, base - 1)
    assert (lanes[1].left_boundary, lanes[1].right_boundary) == (base - 1, base - 2)
    assert lane1.driving and lane1.along_s
    gt = M.lanes_ground_truth(lanes, boundaries)
    assert gt.lane_boundary[1].classification.type == LaneBoundary.Classification.TYPE_DASHED_LINE
    assert gt.lane[0].classification.centerline_is_driving_direction


@settings(max_examples=300, deadline=None)
@given(steer=st.floats(-0.5, 0.5), accel=st.floats(-9.0, 4.0), speed=st.floats(0.5, 40.0),
       heading=st.floats(-math.pi, math.pi), x=st.floats(-1e4, 1e4), t=st.floats(0.0, 3600.0))
def test_follow_recovers_the_command_of_a_rollout(steer, accel, speed, heading, x, t):
    """The reference server's MotionRequest (a kinematic bicycle's state 0.5 s ahead under a
    command) gives that command back through the twin's follower, whenever the vehicle
    moves more than the follower's 5 cm in that time."""
    from addt_dsl.stack.osi_server import motion_request, rollout

    pose = (x, -x / 3, heading, speed)
    end = rollout(pose, steer, accel, 2.7)
    if math.hypot(end[0] - pose[0], end[1] - pose[1]) < 0.1:
        return
    mr = motion_request(t, pose, steer, accel, 2.7)
    got = M.follow(M.targets_from_motion_request(mr), pose, t, 2.7)
    assert got[0] == pytest.approx(steer, abs=1e-6)
    assert got[1] == pytest.approx(accel, abs=1e-6)


@given(st.floats(0.0, 1e6))
def test_timestamps_round_trip_to_the_nanosecond(t):
    sv = SensorView()
    M.set_timestamp(sv.timestamp, t)
    assert 0 <= sv.timestamp.nanos < 1_000_000_000
    assert abs(M.seconds(sv.timestamp) - t) <= 1e-9 + 1e-15 * t


def test_signs_are_traffic_signs_facing_the_traffic():
    from osi3.osi_trafficsign_pb2 import TrafficSign

    gt = M.signs_ground_truth([("stop", 150.0, -1.75, 0.0, 0.0), ("yield", 20.0, 5.0, 1.0, math.pi / 2),
                               ("priority", 40.0, 5.0, 1.0, 0.0)])
    gt = type(gt).FromString(gt.SerializeToString())
    assert [ts.id.value for ts in gt.traffic_sign] == [M.SIGN_ID_BASE + k for k in range(3)]
    types = TrafficSign.MainSign.Classification
    assert [ts.main_sign.classification.type for ts in gt.traffic_sign] == \
        [types.TYPE_STOP, types.TYPE_GIVE_WAY, types.TYPE_RIGHT_OF_WAY_NEXT_INTERSECTION]
    # Facing the traffic that drives towards it: turned half round from the lane's heading.
    assert gt.traffic_sign[0].main_sign.base.orientation.yaw == pytest.approx(math.pi)
    assert gt.traffic_sign[1].main_sign.base.orientation.yaw == pytest.approx(-math.pi / 2)
    assert M.sign_positions(gt) == [("stop", 150.0, -1.75), ("yield", 20.0, 5.0), ("priority", 40.0, 5.0)]


def test_the_priority_signs_cross_osi_as_three_types_and_back():
    from osi3.osi_trafficsign_pb2 import TrafficSign

    types = TrafficSign.MainSign.Classification
    signs = [("priority", 40.0, 5.0), ("priority_road", 60.0, 5.0), ("priority_road_end", 80.0, 5.0)]
    gt = M.signs_ground_truth([(kind, x, y, 0.0, 0.0) for kind, x, y in signs])
    gt = type(gt).FromString(gt.SerializeToString())
    # StVO 301, 306, 307 as OSI names them.
    assert [ts.main_sign.classification.type for ts in gt.traffic_sign] == \
        [types.TYPE_RIGHT_OF_WAY_NEXT_INTERSECTION, types.TYPE_RIGHT_OF_WAY_BEGIN, types.TYPE_RIGHT_OF_WAY_END]
    assert M.sign_positions(gt) == signs
