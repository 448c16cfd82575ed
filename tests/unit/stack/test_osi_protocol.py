"""The OSI framing (osi_transport), the reference OSI server against hostile clients, and the
compiler's rules for `stack external protocol osi`."""

import json
import socket
import struct
import time

import pytest

pytest.importorskip("osi3", reason="the `osi` extra (osi-python) is not installed")

from osi3.osi_sensorview_pb2 import SensorView  # noqa: E402

from addt_dsl.compiler import compile_source  # noqa: E402
from addt_dsl.stack import osi_mapping as M  # noqa: E402
from addt_dsl.stack import osi_transport as T  # noqa: E402
from addt_dsl.stack.bridge import ExternalStack, ProtocolError  # noqa: E402
from addt_dsl.stack.bridge_server import Limits  # noqa: E402
from addt_dsl.stack.osi_server import start_in_thread  # noqa: E402


def test_frame_layout():
    # u32 big-endian length of type + payload, the type byte, the payload.
    assert T.frame(T.BYE) == b"\x00\x00\x00\x01\x07"
    assert T.frame(T.SENSOR_VIEW, b"ab") == b"\x00\x00\x00\x03\x03ab"


class _Bytes:
    """A socket stand-in that yields fixed bytes."""

    def __init__(self, data: bytes):
        self.data, self.read = data, 0

    def settimeout(self, _):
        pass

    def recv_into(self, view, n):
        chunk = self.data[self.read:self.read + n]
        view[:len(chunk)] = chunk
        self.read += len(chunk)
        return len(chunk)


def test_receive_checks_length_and_type_before_the_payload():
    sock = _Bytes(struct.pack(">IB", 1 << 30, T.SENSOR_VIEW))
    with pytest.raises(ProtocolError, match="exceeds the limit"):
        T.recv_message(sock, max_bytes=1 << 20)
    assert sock.read == 4  # only the prefix was read
    with pytest.raises(ProtocolError, match="unknown message type 99"):
        T.recv_message(_Bytes(struct.pack(">IB", 3, 99) + b"xx"))
    with pytest.raises(ProtocolError, match="no type"):
        T.recv_message(_Bytes(struct.pack(">I", 0)))
    big_json = struct.pack(">IB", T.MAX_JSON_BYTES + 2, T.HELLO)
    with pytest.raises(ProtocolError, match="hello of"):
        T.recv_message(_Bytes(big_json))
    assert T.recv_message(_Bytes(T.frame(T.MOTION_REQUEST, b"xyz"))) == (T.MOTION_REQUEST, b"xyz")


def test_payload_parsing_refuses_garbage():
    with pytest.raises(ProtocolError, match="malformed SensorView"):
        T.parse_proto(b"\xff\xff\xff", SensorView)
    with pytest.raises(ProtocolError, match="not a JSON object"):
        T.parse_json(b"[1]", T.HELLO)
    with pytest.raises(ProtocolError, match="malformed JSON"):
        T.parse_json(b"\xc3(", T.HELLO)


def test_concatenated_views_merge_the_static_lanes():
    """The client appends the run's lanes (a SensorView's bytes) to each view's bytes:
    protobuf merges them into one message."""
    static = SensorView()
    static.global_ground_truth.lane.add().id.value = 77
    view = M.WorldView(1.0, M.ObjectState(1, "ego", 1.0, 2.0, 0.75, 0.0, 5.0, 0.0, 4.6, 1.9, 1.5))
    sv = M.sensor_view(view, view.host, 1.5)
    merged = SensorView.FromString(sv.SerializeToString() + static.SerializeToString())
    assert [ln.id.value for ln in merged.global_ground_truth.lane] == [77]
    assert merged.global_ground_truth.moving_object[0].base.position.x == 1.0
    assert M.seconds(merged.timestamp) == 1.0


# ---------------------------------------------------------------- the reference server, hostile clients

@pytest.fixture()
def server(capsys):
    srv = start_in_thread("127.0.0.1:0", Limits(token="s3cret", max_message_bytes=1 << 16, idle_timeout_s=1.0))
    yield srv
    srv.shutdown()
    srv.server_close()
    assert "Traceback" not in capsys.readouterr().err


def _reply(sock) -> tuple[int, dict]:
    kind, payload = T.recv_message(sock, deadline=time.monotonic() + 5)
    return kind, (json.loads(payload) if kind in T.JSON_TYPES else {})


def _closed(sock) -> bool:
    sock.settimeout(5)
    try:
        return sock.recv(1) == b""
    except ConnectionResetError:
        return True


def _hello(**over) -> dict:
    hello = {"type": "hello", "protocol": "addt-osi", "version": 1, "token": "s3cret", "answer": "motion_request",
             "step_s": 0.01, "seed": 1, "host_id": 1, "stack": {}, "sensors": [{"name": "lidar", "kind": "lidar"}]}
    hello.update(over)
    return hello


@pytest.mark.parametrize("over, message", [
    ({"token": "wrong"}, "wrong or missing token"),
    ({"version": 2}, "not supported"),
    ({"answer": "teleport"}, "'answer' must be one of"),
    ({"stack": {"cruise_speed": 1e9}}, "outside"),
    ({"sensors": []}, "lidar"),
])
def test_bad_hellos_get_an_error_and_a_close(server, over, message):
    with socket.create_connection(server.server_address[:2], timeout=5) as s:
        T.send_json(s, T.HELLO, _hello(**over))
        kind, reply = _reply(s)
        assert kind == T.ERROR and message in reply["message"]
        assert _closed(s)


def test_oversized_and_early_messages_are_refused(server):
    with socket.create_connection(server.server_address[:2], timeout=5) as s:
        s.sendall(struct.pack(">IB", 1 << 20, T.SENSOR_VIEW))
        kind, reply = _reply(s)
        assert kind == T.ERROR and "exceeds the limit" in reply["message"]
        assert _closed(s)
    with socket.create_connection(server.server_address[:2], timeout=5) as s:
        T.send_message(s, T.SENSOR_VIEW, SensorView().SerializeToString())
        kind, reply = _reply(s)
        assert kind == T.ERROR and "before hello" in reply["message"]


def test_a_silent_client_is_dropped_after_the_idle_timeout(server):
    with socket.create_connection(server.server_address[:2], timeout=5) as s:
        s.sendall(b"\x00\x00")  # half a length prefix, then nothing
        t0 = time.monotonic()
        assert _closed(s)
        assert time.monotonic() - t0 < 4


# ---------------------------------------------------------------- the language

SOURCE = """scenario s {{
  duration 5 s
  road r {{ line length 300 m }}
  ego car on r lane -1 at 10 m speed 20 m/s {{
    stack external protocol osi
{sensor}  }}
  faults {{
{fault}  }}
}}
"""


def _diagnostics(sensor="    sensor lidar\n", fault="    at 1 s drop lidar\n"):
    return compile_source(SOURCE.format(sensor=sensor, fault=fault)).diagnostics


def test_protocol_osi_compiles_with_sensor_faults():
    assert not [d for d in _diagnostics() if d.is_error]
    assert ExternalStack.required_modules({"protocol": "osi"}) == {"protocol": "osi3"}
    assert ExternalStack.required_modules({"protocol": "bridge"}) == {}


def test_stack_internal_faults_with_osi_are_refused_with_the_reason():
    errors = [d for d in _diagnostics(fault="    at 2 s bitflip planner.state bit 0\n") if d.is_error]
    assert [d.code for d in errors] == ["E0109"]
    assert "OSI's messages carry no fault schedule" in errors[0].message
    assert (errors[0].span.line, errors[0].span.col) == (9, 20)  # the target, `planner.state`


def test_protocol_osi_needs_a_lidar():
    errors = [d for d in _diagnostics(sensor="    sensor camera\n", fault="") if d.is_error]
    assert [d.code for d in errors] == ["E0103"] and "lidar" in errors[0].message
