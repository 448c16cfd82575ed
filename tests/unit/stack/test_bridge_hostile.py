"""Hostile peers and clients of the bridge, over loopback: every case ends in bounded time
with a clean refusal (an `error` reply, a closed connection, a StackError), never a traceback."""

import select
import socket
import struct
import threading
import time

import pytest

from addt_dsl.stack.bev import StackError
from addt_dsl.stack.bridge import (
    ALLOW_HOSTS_ENV,
    ProtocolError,
    _control,
    check_address,
    encode,
    escape,
    recv,
    send,
)
from addt_dsl.stack.bridge_server import Limits, start_in_thread


@pytest.fixture()
def server(capsys):
    srv = start_in_thread("127.0.0.1:0", Limits(token="s3cret", max_message_bytes=1 << 16, idle_timeout_s=1.0),
                          max_connections=4)
    yield srv
    srv.shutdown()
    srv.server_close()
    assert "Traceback" not in capsys.readouterr().err


def _connect(srv) -> socket.socket:
    host, port = srv.server_address[:2]
    sock = socket.create_connection((host, port), timeout=5)
    return sock


def _reply(sock) -> dict:
    header, _ = recv(sock, deadline=time.monotonic() + 5)
    return header


def _closed(sock) -> bool:
    sock.settimeout(5)
    try:
        return sock.recv(1) == b""
    except ConnectionResetError:
        return True


def test_huge_length_prefix_is_refused_before_reading(server):
    with _connect(server) as s:
        s.sendall(struct.pack(">I", 4 * 2**30 - 1))
        reply = _reply(s)
        assert reply["type"] == "error" and "exceeds the limit" in reply["message"]
        assert _closed(s)


def test_malformed_json_gets_an_error_reply_and_a_close(server):
    with _connect(server) as s:
        head = b'{"token": "s3cret", not json'  # the token is checked first, on the bytes
        s.sendall(struct.pack(">II", 4 + len(head), len(head)) + head)
        reply = _reply(s)
        assert reply["type"] == "error" and "malformed" in reply["message"]
        assert _closed(s)


def test_slow_loris_times_out_on_the_whole_message_not_per_read(server):
    data = encode({"type": "bye", "pad": "x" * 40})  # 60 bytes: 12 s at one byte per 0.2 s
    with _connect(server) as s:
        t0 = time.monotonic()
        sent = 0
        for b in data:  # each read is quick (0.2 s < the 1 s deadline); the whole message is not
            try:
                s.sendall(bytes([b]))
            except OSError:
                break
            sent += 1
            if select.select([s], [], [], 0.2)[0]:
                break  # the server spoke or closed
        assert _closed(s)
        assert sent < len(data) and time.monotonic() - t0 < 4.0


def test_idle_connections_are_closed(server):
    socks = [_connect(server) for _ in range(3)]
    t0 = time.monotonic()
    assert all(_closed(s) for s in socks)
    assert time.monotonic() - t0 < 4.0
    for s in socks:
        s.close()


def test_connections_beyond_the_limit_are_refused(server):
    held = [_connect(server) for _ in range(4)]
    time.sleep(0.2)
    with _connect(server) as extra:
        assert _reply(extra)["message"].startswith("busy")
    for s in held:
        s.close()


def _hello(**over):
    hello = {"type": "hello", "protocol": 1, "seed": 1, "step_s": 0.01, "token": "s3cret",
             "stack": {"planner_rate": 10.0}, "ego": {}, "sensors": [], "map": {}}
    hello.update(over)
    return hello


@pytest.mark.parametrize("hello, words", [
    (_hello(token="wrong"), "token"),
    (_hello(stack={"planner_rate": 0}), "planner_rate"),
    (_hello(stack={"planner_rate": float("nan")}), "planner_rate"),
    (_hello(stack={"bogus": 1}), "bogus"),
    (_hello(step_s=0), "step_s"),
    (_hello(protocol=99), "protocol"),
])
def test_bad_hello_settings_are_refused(server, hello, words):
    with _connect(server) as s:
        send(s, hello)
        reply = _reply(s)
        assert reply["type"] == "error" and words in reply["message"]
        assert _closed(s)


def test_escape_sequences_in_a_message_type_are_escaped(server):
    with _connect(server) as s:
        send(s, {"type": "\x1b[31mred\x1b[0m", "token": "s3cret"})
        reply = _reply(s)
        assert "\x1b" not in reply["message"] and "\\x1b" in reply["message"]


def test_recv_refuses_a_huge_prefix_without_allocating():
    a, b = socket.socketpair()
    with a, b:
        a.sendall(struct.pack(">I", 2**32 - 1))
        with pytest.raises(ProtocolError):
            recv(b, max_bytes=1 << 20, deadline=time.monotonic() + 1)


def test_random_bytes_end_the_session_cleanly(server):
    with _connect(server) as s:
        s.sendall(bytes(range(64)))  # a 66,051-byte prefix over a 64 KiB limit, then garbage
        assert _reply(s)["type"] == "error"
        assert _closed(s)


# ---- the runner's side: what a hostile server can send back

@pytest.mark.parametrize("reply", [
    {"commands": [[float("nan"), 0.0, 0.0]]},
    {"commands": [[1.0, float("inf"), 0.0]]},
    {"command": [0.0, float("nan")]},
    {"latency": {"e2e": float("inf")}},
    {"events": [[float("nan"), "x", {}]]},
    {"commands": "not a list of triples"},
    {"commands": [[1.0, "0.1", 0.0]]},
])
def test_non_finite_or_malformed_commands_are_stack_failures(reply):
    with pytest.raises(StackError):
        _control({"type": "control", **reply}, 0.0)


def test_peer_text_in_events_is_escaped():
    _, _, _, _, events = _control({"type": "control", "events": [[0.0, "k\x1b]0;x\x07", {"m": "\x1b[2J"}]]}, 0.0)
    (_, kind, detail), = events
    assert "\x1b" not in kind and "\x07" not in kind and detail == {"m": "\\x1b[2J"}
    assert escape("ok \u00e9") == "ok \u00e9"


def test_scenario_addresses_must_be_loopback_unless_allowed(monkeypatch):
    monkeypatch.delenv(ALLOW_HOSTS_ENV, raising=False)
    for host in ("127.0.0.1", "localhost", "::1", "127.1.2.3"):
        check_address(host)
    for host in ("10.0.0.1", "example.com", "0.0.0.0"):
        with pytest.raises(StackError, match="--allow-host"):
            check_address(host)
    monkeypatch.setenv(ALLOW_HOSTS_ENV, "10.0.0.1")
    check_address("10.0.0.1")


def test_server_warns_when_it_binds_beyond_loopback(capsys):
    srv = start_in_thread("0.0.0.0:0")
    try:
        assert "not loopback" in capsys.readouterr().err
    finally:
        srv.shutdown()
        srv.server_close()


# ---- end to end: a hostile remote stack drives a real run

def _hostile_remote(reply: dict):
    """A server that says `ready`, then answers the first step with `reply`."""
    listener = socket.create_server(("127.0.0.1", 0))

    def serve():
        conn, _ = listener.accept()
        with conn:
            recv(conn)
            send(conn, {"type": "ready"})
            recv(conn)
            send(conn, reply)
            try:
                recv(conn, deadline=time.monotonic() + 5)
            except (OSError, ValueError):
                pass
        listener.close()

    threading.Thread(target=serve, daemon=True).start()
    return "127.0.0.1:%d" % listener.getsockname()[1]


SCENARIO = """
scenario hostile_remote {
  duration 1 s
  road r {
    line length 200 m
    lanes right 1
  }
  ego car on r lane -1 at 10 m speed 10 m/s {
    stack external address "%s" timeout 5 s
  }
}
"""


@pytest.mark.parametrize("reply, words", [
    ({"type": "control", "commands": [[float("nan"), 0.0, 0.0]]}, "non-finite"),
    ({"type": "error", "message": "boom \x1b[2J\x1b]0;pwned\x07"}, "boom \\x1b[2J"),
])
def test_a_hostile_remote_makes_the_run_detected_with_escaped_text(reply, words):
    from addt_dsl.compiler import compile_source
    from addt_dsl.runtime.execute import execute
    from addt_dsl.sweep import expand

    plan = compile_source(SCENARIO % _hostile_remote(reply)).plan
    result = execute(expand(plan).specs[0])
    assert result.status == "detected" and words in result.error
    assert "\x1b" not in result.error and "\x07" not in result.error


def test_a_refused_address_is_reported_without_connecting(monkeypatch):
    from addt_dsl.compiler import compile_source
    from addt_dsl.runtime.execute import execute
    from addt_dsl.sweep import expand

    monkeypatch.delenv(ALLOW_HOSTS_ENV, raising=False)
    result = execute(expand(compile_source(SCENARIO % "192.0.2.1:5555").plan).specs[0])
    assert result.status == "detected" and "--allow-host 192.0.2.1" in result.error
