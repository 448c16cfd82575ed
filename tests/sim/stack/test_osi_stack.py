"""`stack external protocol osi` closed loop: what the SensorViews carry under sensor faults,
peers that misbehave, and determinism. A scripted peer on a thread records each view."""

import json
import math
import socket
import threading
import time

import pytest

pytest.importorskip("osi3", reason="the `osi` extra (osi-python) is not installed")

from osi3.osi_motionrequest_pb2 import MotionRequest  # noqa: E402
from osi3.osi_sensorview_pb2 import SensorView  # noqa: E402

from addt_dsl.compiler import compile_source  # noqa: E402
from addt_dsl.runtime.execute import execute  # noqa: E402
from addt_dsl.stack import osi_mapping as M  # noqa: E402
from addt_dsl.stack import osi_transport as T  # noqa: E402
from addt_dsl.stack.bridge import ALLOW_HOSTS_ENV  # noqa: E402
from addt_dsl.stack.osi_server import start_in_thread  # noqa: E402
from addt_dsl.sweep import expand  # noqa: E402

SOURCE = """scenario s {{
  duration {duration}
  seed 5
  road r {{
    line length 400 m
    lanes right 2 width 3.5 m
  }}
  ego car on r lane -1 at 10 m speed 15 m/s {{
    stack external protocol osi address "{address}" timeout {timeout}
    sensor lidar rate 10 Hz rays 360 range 80 m
  }}
  agent lead car on r lane -1 at 50 m speed 15 m/s {{
    behavior cruise speed 15 m/s
  }}
  faults {{
{faults}  }}
  expect {{ no collision }}
}}
"""


def hold(sv: SensorView) -> tuple[int, bytes]:
    """Keep the speed, straight ahead: a desired state 0.5 s along the heading."""
    loc = sv.host_vehicle_data.location
    v = math.hypot(loc.velocity.x, loc.velocity.y)
    yaw = loc.orientation.yaw
    mr = MotionRequest()
    mr.motion_request_type = MotionRequest.MOTION_REQUEST_TYPE_DESIRED_STATE
    d = mr.desired_state
    M.set_timestamp(d.timestamp, M.seconds(sv.host_vehicle_data.timestamp) + 0.5)
    d.position.x = loc.position.x + 0.5 * v * math.cos(yaw)
    d.position.y = loc.position.y + 0.5 * v * math.sin(yaw)
    d.orientation.yaw = yaw
    d.velocity.x, d.velocity.y = v * math.cos(yaw), v * math.sin(yaw)
    return T.MOTION_REQUEST, mr.SerializeToString()


class Peer:
    """A scripted OSI stack: answers hello with `ready`, each view with `answer(view)`."""

    def __init__(self, answer=hold, ready=None):
        self.answer, self.ready = answer, ready or {"version": 1}
        self.views: list[SensorView] = []
        self.hello: dict = {}
        self.listener = socket.create_server(("127.0.0.1", 0))
        self.address = "127.0.0.1:%d" % self.listener.getsockname()[1]
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self):
        conn, _ = self.listener.accept()
        self.listener.close()  # one run per peer
        with conn:
            try:
                kind, payload = T.recv_message(conn)
                self.hello = json.loads(payload)
                T.send_json(conn, T.READY, self.ready)
                while True:
                    kind, payload = T.recv_message(conn)
                    if kind == T.BYE:
                        return
                    sv = SensorView.FromString(payload)
                    self.views.append(sv)
                    reply = self.answer(sv)
                    if reply is None:
                        time.sleep(10)
                        return
                    conn.sendall(T.frame(*reply) if isinstance(reply, tuple) else reply)
            except (ConnectionError, OSError, ValueError):
                return


def run(peer_address: str, faults: str = "", duration: str = "3 s", timeout: str = "5 s"):
    result = compile_source(SOURCE.format(address=peer_address, faults=faults, duration=duration, timeout=timeout))
    assert result.ok, result.diagnostics
    return execute(expand(result.plan).specs[0])


def _stamps(peer):
    return [(round(M.seconds(v.host_vehicle_data.timestamp), 6), round(M.seconds(v.timestamp), 6))
            for v in peer.views]


def test_views_carry_the_world_lanes_and_host():
    peer = Peer()
    res = run(peer.address)
    assert res.status == "ok", res.error
    assert peer.hello["protocol"] == "addt-osi" and peer.hello["answer"] == "motion_request"
    assert len(peer.views) == 300  # one per step: 0 .. 2.99 s at 10 ms (the last sample ends the run)
    sv = peer.views[0]
    gt = sv.global_ground_truth
    assert gt.host_vehicle_id.value == 1 and [o.id.value for o in gt.moving_object] == [1, 2]
    lead = gt.moving_object[1].base
    # The lead's box centre at 50 m on lane -1 (t = -1.75 m), moving at 15 m/s along +x.
    assert (lead.position.x, lead.position.y) == pytest.approx((50.0, -1.75))
    assert lead.velocity.x == pytest.approx(15.0) and lead.dimension.length == pytest.approx(4.6)
    assert len(gt.lane) == 2 and len(gt.lane_boundary) == 3
    # Lidar at 10 Hz: a new view every 0.1 s, the same one (its own stamp) in between.
    assert _stamps(peer)[:12] == [(round(0.01 * k, 6), round(0.1 * (k // 10), 6)) for k in range(12)]
    # The peer asks for no acceleration and the speed it has: the follower commands 0 and
    # only drag (0.0004 v^2 per unit mass) slows the ego: v = 15 / (1 + 0.0004 * 15 * 2.99).
    assert res.trace.actors["ego"].speed[-1] == pytest.approx(15.0 / (1 + 0.0004 * 15 * 2.99), abs=0.01)
    assert abs(res.trace.actors["ego"].y - -1.75).max() < 0.01


def test_a_dropped_frame_resends_the_previous_view_with_its_stamp():
    peer = Peer()
    res = run(peer.address, "    during [1 s, 1.35 s] drop lidar rate 1\n")
    assert res.status == "ok", res.error
    stamps = dict(_stamps(peer))
    assert stamps[1.0] == 0.9 and stamps[1.35] == 0.9  # frames at 1.0 .. 1.3 s withheld
    assert stamps[1.4] == 1.4


def test_a_delay_sends_an_older_view_and_a_shift_moves_the_objects():
    peer = Peer()
    run(peer.address, "    during [1 s, 3 s] delay lidar by 0.25 s\n")
    stamps = dict(_stamps(peer))
    assert stamps[1.2] == 0.9 and stamps[1.25] == 1.0  # the 1.0 s frame arrives at 1.25 s
    # The view sent at 1.25 s is the world of 1.0 s: the lead where it was then.
    view = next(v for v in peer.views if M.seconds(v.host_vehicle_data.timestamp) == pytest.approx(1.25))
    assert view.global_ground_truth.moving_object[1].base.position.x == pytest.approx(50.0 + 15.0 * 1.0, abs=0.01)
    clean, shifted = Peer(), Peer()
    run(clean.address, duration="1.5 s")
    run(shifted.address, "    at 1 s shift lidar yaw 0.05 rad\n", duration="1.5 s")

    def lead_at(peer, t):
        v = next(v for v in peer.views if M.seconds(v.timestamp) == pytest.approx(t))
        return v.global_ground_truth.moving_object[1].base

    assert lead_at(shifted, 0.9).position.y == pytest.approx(lead_at(clean, 0.9).position.y, abs=1e-9)
    a, b = lead_at(clean, 1.2), lead_at(shifted, 1.2)
    # Seen through a mount turned 0.05 rad left, mapped back through the calibrated one:
    # the lead about 41 m ahead appears 41 m * -sin(0.05) ~ -2.0 m to the side.
    ahead = a.position.x - peer.views[0].global_ground_truth.moving_object[0].base.position.x
    assert b.position.y - a.position.y == pytest.approx(-2.0, abs=0.3) and ahead > 30
    assert b.orientation.yaw == pytest.approx(a.orientation.yaw - 0.05)


def lane_change(sv: SensorView) -> tuple[int, bytes]:
    """A trajectory along lane -2's centre (y = -5.25 m) at the host's speed, points every 0.2 s."""
    loc = sv.host_vehicle_data.location
    now = M.seconds(sv.host_vehicle_data.timestamp)
    v = math.hypot(loc.velocity.x, loc.velocity.y)
    mr = MotionRequest()
    mr.motion_request_type = MotionRequest.MOTION_REQUEST_TYPE_TRAJECTORY
    for k in range(1, 11):
        p = mr.desired_trajectory.trajectory_point.add()
        M.set_timestamp(p.timestamp, now + 0.2 * k)
        p.position.x, p.position.y = loc.position.x + v * 0.2 * k + 10.0, -5.25
    return T.MOTION_REQUEST, mr.SerializeToString()


def test_a_desired_trajectory_is_followed_into_the_next_lane():
    res = run(Peer(lane_change).address, duration="6 s")
    assert res.status == "ok", res.error
    ego = res.trace.actors["ego"]
    assert ego.y[0] == pytest.approx(-1.75)
    assert ego.y[-1] == pytest.approx(-5.25, abs=0.1)  # lane -2's centre
    assert abs(ego.heading[-1]) < 0.02 and ego.speed[-1] > 14.0


def mover(sv: SensorView) -> tuple[int, bytes]:
    """TrafficUpdate: the host 1 m/s^2 faster each second along +x from where it is, at the next step."""
    from osi3.osi_trafficupdate_pb2 import TrafficUpdate

    loc = sv.host_vehicle_data.location
    now = M.seconds(sv.host_vehicle_data.timestamp)
    tu = TrafficUpdate()
    M.set_timestamp(tu.timestamp, now + 0.01)
    u = tu.update.add()
    u.id.value = 1
    v = loc.velocity.x
    u.base.position.x, u.base.position.y = loc.position.x + v * 0.01 + 0.5 * 0.01 ** 2, -1.75
    u.base.orientation.yaw = 0.0
    u.base.velocity.x, u.base.acceleration.x = v + 0.01, 1.0
    return T.TRAFFIC_UPDATE, tu.SerializeToString()


def test_a_traffic_update_moves_the_host():
    result = compile_source(SOURCE.format(address=Peer(mover).address, faults="", duration="2 s", timeout="5 s")
                            .replace("timeout 5 s", "timeout 5 s answer traffic_update"))
    assert result.ok, result.diagnostics
    res = execute(expand(result.plan).specs[0])
    assert res.status == "ok", res.error
    ego = res.trace.actors["ego"]
    # x = 10 + 15 t + t^2 / 2 (constant 1 m/s^2 from 15 m/s), speed 15 + t: by hand at 2 s, 42 m and 17 m/s.
    assert ego.x[-1] == pytest.approx(42.0, abs=1e-6) and ego.speed[-1] == pytest.approx(17.0, abs=1e-9)
    assert (ego.y == -1.75).all() and ego.accel[-1] == pytest.approx(1.0)


@pytest.mark.parametrize("answer, message", [
    (lambda sv: (T.TRAFFIC_UPDATE, b""), "sent TrafficUpdate, expected MotionRequest"),
    (lambda sv: (T.MOTION_REQUEST, b"\xff\xff\xff"), "malformed MotionRequest"),
    (lambda sv: (T.MOTION_REQUEST, MotionRequest().SerializeToString()), "lacks timestamp"),
    (lambda sv: (T.ERROR, json.dumps({"message": "boom\x1b[31m"}).encode()), "OSI stack error: boom\\x1b[31m"),
    (lambda sv: T.frame(T.MOTION_REQUEST)[:3], "TimeoutError"),  # half a prefix, then silence
])
def test_a_misbehaving_peer_ends_the_run_detected(answer, message):
    peer = Peer(answer)
    t0 = time.monotonic()
    res = run(peer.address, timeout="1 s")
    assert res.status == "detected"
    assert message in res.error
    assert time.monotonic() - t0 < 5
    assert "\x1b" not in res.error


def test_a_peer_of_another_version_and_a_remote_address_are_refused(monkeypatch):
    res = run(Peer(ready={"version": 9}).address)
    assert res.status == "detected" and "answered version 9" in res.error
    monkeypatch.delenv(ALLOW_HOSTS_ENV, raising=False)
    res = run("192.0.2.1:5556")
    assert res.status == "detected" and "must be loopback" in res.error


@pytest.mark.slow
def test_the_reference_server_gives_one_digest_per_spec():
    server = start_in_thread()
    try:
        digests = {run(server.address, "    drop lidar rate 0.2\n", duration="6 s").digest for _ in range(2)}
    finally:
        server.shutdown()
        server.server_close()
    assert len(digests) == 1
