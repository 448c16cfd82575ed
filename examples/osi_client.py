"""A minimal OSI driving function for `stack external protocol osi` (copy it to start yours).

    python examples/osi_client.py [HOST:PORT]      # default 127.0.0.1:5556; prints "listening ..."

Needs only osi-python. Per SensorView it keeps the lane whose centre line is nearest and
follows the nearest object ahead in it at a 2 s gap, answering with a MotionRequest (a
desired state 1 s ahead on the centre line). Framing: u32 big-endian length, u8 type, payload.
"""

import json
import math
import socket
import struct
import sys

from osi3.osi_motionrequest_pb2 import MotionRequest
from osi3.osi_sensorview_pb2 import SensorView

HELLO, READY, SENSOR_VIEW, MOTION_REQUEST, ERROR, BYE = 1, 2, 3, 5, 6, 7
CRUISE, GAP_S, HORIZON_S = 20.0, 2.0, 1  # [m/s], [s], [s] (whole seconds)


def read(sock):
    head = sock.recv(4, socket.MSG_WAITALL)
    if len(head) < 4:
        raise ConnectionError("closed")
    (length,) = struct.unpack(">I", head)
    data = sock.recv(length, socket.MSG_WAITALL) if 1 <= length <= 16 * 2**20 else b""
    if len(data) != length or not data:
        raise ValueError(f"bad message of {length} bytes")
    return data[0], data[1:]


def write(sock, kind, payload):
    sock.sendall(struct.pack(">IB", 1 + len(payload), kind) + payload)


def decide(sv: SensorView) -> MotionRequest:
    me = sv.host_vehicle_data.location
    x, y, yaw = me.position.x, me.position.y, me.orientation.yaw
    v = math.hypot(me.velocity.x, me.velocity.y)
    c, s = math.cos(yaw), math.sin(yaw)
    gt = sv.global_ground_truth
    # The lane whose centre line passes nearest, its points in our driving direction.
    lanes = [[(p.x, p.y) for p in ln.classification.centerline] for ln in gt.lane]
    line = min(lanes, key=lambda pts: min(math.hypot(px - x, py - y) for px, py in pts))
    if c * (line[-1][0] - line[0][0]) + s * (line[-1][1] - line[0][1]) < 0:
        line = line[::-1]
    # Objects ahead within our lane's width: follow the nearest at GAP_S.
    speed = CRUISE
    for o in gt.moving_object:
        if o.id.value == sv.host_vehicle_id.value:
            continue
        dx, dy = o.base.position.x - x, o.base.position.y - y
        ahead, side = c * dx + s * dy, -s * dx + c * dy
        if ahead > 0 and abs(side) < 1.8:
            gap = ahead - 0.5 * (o.base.dimension.length + 4.6)
            speed = min(speed, max(0.0, (gap - 5.0) / GAP_S))
    accel = max(-6.0, min(2.0, (speed - v) / 2.0))
    # The desired state: HORIZON_S ahead along the centre line.
    reach = max(v * HORIZON_S, 3.0)
    start = min(range(len(line)), key=lambda k: math.hypot(line[k][0] - x, line[k][1] - y))
    tx, ty = next((p for p in line[start:] if c * (p[0] - x) + s * (p[1] - y) >= reach), line[-1])
    heading = math.atan2(ty - y, tx - x)
    mr = MotionRequest(motion_request_type=MotionRequest.MOTION_REQUEST_TYPE_DESIRED_STATE)
    d = mr.desired_state
    d.timestamp.CopyFrom(sv.host_vehicle_data.timestamp)
    d.timestamp.seconds += HORIZON_S
    d.position.x, d.position.y, d.orientation.yaw = tx, ty, heading
    d.velocity.x, d.velocity.y = speed * math.cos(heading), speed * math.sin(heading)
    d.acceleration.x, d.acceleration.y = accel * math.cos(heading), accel * math.sin(heading)
    return mr


def main(address="127.0.0.1:5556"):
    host, port = address.rsplit(":", 1)
    with socket.create_server((host, int(port))) as server:
        print("listening %s:%d" % server.getsockname()[:2], flush=True)
        while True:
            conn, _ = server.accept()
            with conn:
                try:
                    kind, payload = read(conn)
                    hello = json.loads(payload) if kind == HELLO else {}
                    if hello.get("answer") != "motion_request" or hello.get("version") != 1:
                        write(conn, ERROR, json.dumps({"message": "I answer motion_request, version 1"}).encode())
                        continue
                    write(conn, READY, json.dumps({"version": 1}).encode())
                    while (msg := read(conn))[0] == SENSOR_VIEW:
                        write(conn, MOTION_REQUEST, decide(SensorView.FromString(msg[1])).SerializeToString())
                except (ConnectionError, ValueError) as exc:
                    print("run ended:", exc, file=sys.stderr)


if __name__ == "__main__":
    main(*sys.argv[1:])
