"""Lock-step TCP framing for `stack external protocol osi` (docs/bridge.md#osi-protocol).

Every message, both directions:

    u32 big-endian  N: length of the rest (the type byte and the payload)
    u8              message type (`HELLO` ... `BYE`)
    N - 1 bytes     payload: an osi3 protobuf message, or UTF-8 JSON for HELLO, READY, ERROR

The simulator opens with HELLO (`{"protocol": "addt-osi", "version": 1, "osi_version",
"answer", "step_s", "seed", "token"?, ...}`), the stack answers READY (`{"version": 1}`);
then per physics step one SENSOR_VIEW and one reply of the type HELLO declared
(MOTION_REQUEST or TRAFFIC_UPDATE); BYE ends the run; ERROR (`{"message"}`) from either
side ends it with that message. The length prefix is checked against the receiver's limit
before any of the message is read; payloads are decoded only after the whole message
arrived within its deadline. Nothing from the peer is printed or stored unescaped.
"""

from __future__ import annotations

import json
import socket
import struct
import time

from addt_dsl.stack.bridge import ProtocolError, recv_exact, escape

PROTOCOL_NAME = "addt-osi"
VERSION = 1  # of this framing and handshake
MAX_MESSAGE_BYTES = 16 * 2**20  # default limit on one message (a SensorView with a map's lanes is < 1 MB)
MAX_JSON_BYTES = 1 * 2**20  # HELLO, READY and ERROR are small; a bigger one is refused before parsing

HELLO, READY, SENSOR_VIEW, TRAFFIC_UPDATE, MOTION_REQUEST, ERROR, BYE = 1, 2, 3, 4, 5, 6, 7
TYPE_NAMES = {HELLO: "hello", READY: "ready", SENSOR_VIEW: "SensorView", TRAFFIC_UPDATE: "TrafficUpdate",
              MOTION_REQUEST: "MotionRequest", ERROR: "error", BYE: "bye"}
JSON_TYPES = (HELLO, READY, ERROR)
# `stack external ... answer WORD` -> the reply type the stack must send after each SensorView.
ANSWERS = {"motion_request": MOTION_REQUEST, "traffic_update": TRAFFIC_UPDATE}
_PREFIX = struct.Struct(">IB")


def frame(kind: int, payload: bytes = b"") -> bytes:
    return _PREFIX.pack(1 + len(payload), kind) + payload


def send_message(sock: socket.socket, kind: int, payload: bytes = b"", deadline: float | None = None) -> None:
    if deadline is not None:
        left = deadline - time.monotonic()
        if left <= 0:
            raise TimeoutError("no time left to send")
        sock.settimeout(left)
    sock.sendall(frame(kind, payload))


def send_json(sock: socket.socket, kind: int, obj: dict, deadline: float | None = None) -> None:
    send_message(sock, kind, json.dumps(obj, separators=(",", ":"), allow_nan=False).encode(), deadline)


def recv_message(sock: socket.socket, max_bytes: int = MAX_MESSAGE_BYTES,
                 deadline: float | None = None) -> tuple[int, bytes]:
    """(type, payload) of one whole message that arrived before `deadline`; ProtocolError
    for a length over `max_bytes` (before reading it), an empty message or an unknown type."""
    (length,) = struct.unpack(">I", recv_exact(sock, 4, deadline))
    if length > max_bytes:
        raise ProtocolError(f"message of {length} bytes exceeds the limit of {max_bytes} bytes")
    if length < 1:
        raise ProtocolError("message of 0 bytes has no type")
    kind = recv_exact(sock, 1, deadline)[0]
    if kind not in TYPE_NAMES:
        raise ProtocolError(f"unknown message type {kind}")
    if kind in JSON_TYPES and length - 1 > MAX_JSON_BYTES:
        raise ProtocolError(f"{TYPE_NAMES[kind]} of {length - 1} bytes exceeds {MAX_JSON_BYTES} bytes")
    return kind, recv_exact(sock, length - 1, deadline)


def parse_json(payload: bytes, kind: int) -> dict:
    try:
        obj = json.loads(payload.decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise ProtocolError(f"{TYPE_NAMES[kind]}: malformed JSON: {escape(str(exc), 200)}") from None
    if not isinstance(obj, dict):
        raise ProtocolError(f"{TYPE_NAMES[kind]}: not a JSON object")
    return obj


def parse_proto(payload: bytes, cls):
    """An osi3 message from its bytes; ProtocolError if they do not parse."""
    from google.protobuf.message import DecodeError

    try:
        return cls.FromString(payload)
    except (DecodeError, RecursionError, ValueError) as exc:
        raise ProtocolError(f"malformed {cls.__name__}: {escape(str(exc), 200)}") from None
