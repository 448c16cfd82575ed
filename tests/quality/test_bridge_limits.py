"""The bridge decodes nothing beyond its limits, checks a server's token before it parses a
hello, bounds what a peer's reply may ask of a run, and refuses addresses it cannot use.

Bounded: every case ends within seconds; memory is measured with tracemalloc (which sees
the server's threads too). Before: a 60 MiB reply of `[{},{},...]` cost a run 1.8 GB, the
reference server parsed a hello of that size (1.7 GB) before checking the token, 20,000
events per step turned a 6 s run into exit 3 after 245 s, `port 99999` became 34463 and
`[::1]` passed the loopback check and could not resolve."""

from __future__ import annotations

import socket
import struct
import threading
import time
import tracemalloc

import pytest

from addt_dsl.stack.bev import StackError
from addt_dsl.stack.bridge import (
    MAX_EVENTS_PER_STEP,
    ProtocolError,
    _control,
    decode,
    is_loopback,
    parse_address,
    recv,
    send,
)
from addt_dsl.stack.bridge_server import Limits, start_in_thread

MIB = 2**20


def _brackets(n_bytes: int, prefix: bytes = b"") -> bytes:
    """A header of `n_bytes` that is `prefix` then `{},{},...`: cheap bytes, costly JSON."""
    body = b"{},"
    n = (n_bytes - len(prefix) - 3) // len(body)
    return prefix + b'"x":[' + body * n + b"{}]}"


def _message(head: bytes) -> bytes:
    return struct.pack(">II", 4 + len(head), len(head)) + head


def _peak_bytes(fn) -> int:
    tracemalloc.start()
    try:
        fn()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_a_huge_json_reply_is_refused_before_it_is_parsed():
    payload = _message(_brackets(20 * MIB, b'{"type":"control",'))
    a, b = socket.socketpair()
    errors: list = []

    def read():
        try:
            with pytest.raises(ProtocolError, match="exceeds the limit"):
                recv(b, deadline=time.monotonic() + 10)
        except BaseException as exc:  # noqa: BLE001 - reported below
            errors.append(exc)

    def run():
        reader = threading.Thread(target=read)
        reader.start()
        a.sendall(payload)
        reader.join(15)

    t0 = time.perf_counter()
    with a, b:
        peak = _peak_bytes(run)
    assert not errors, errors
    # The bytes themselves (20 MiB, read once) and nothing of the ~7 million objects.
    assert peak < 3 * len(payload), peak
    assert time.perf_counter() - t0 < 10


def test_header_limits_apply_before_parsing():
    small = _brackets(64 * 1024, b"{")
    with pytest.raises(ProtocolError, match="objects or lists"):
        decode(_message(small)[4:], max_header_bytes=None, max_containers=1000)
    with pytest.raises(ProtocolError, match="exceeds the limit"):
        decode(_message(small)[4:], max_header_bytes=1000)
    header, blobs = decode(_message(b'{"type":"ok","x":[{},{}]}')[4:])
    assert header == {"type": "ok", "x": [{}, {}]} and blobs == {}


def test_the_server_checks_the_token_before_it_parses_a_hello(capsys):
    srv = start_in_thread("127.0.0.1:0", Limits(token="s3cret", max_message_bytes=64 * MIB, idle_timeout_s=10.0))
    try:
        hello = _message(_brackets(20 * MIB, b'{"type":"hello",'))
        host, port = srv.server_address[:2]

        def attack():
            with socket.create_connection((host, port), timeout=10) as s:
                s.sendall(hello)
                reply, _ = recv(s, deadline=time.monotonic() + 10)
                assert reply["type"] == "error" and "token" in reply["message"]

        t0 = time.perf_counter()
        peak = _peak_bytes(attack)
        assert peak < 3 * len(hello), peak
        assert time.perf_counter() - t0 < 10
        # With the token, the same bytes are parsed, and refused by the container bound.
        with socket.create_connection((host, port), timeout=10) as s:
            s.sendall(_message(_brackets(2 * MIB, b'{"type":"hello","token":"s3cret",')))
            reply, _ = recv(s, deadline=time.monotonic() + 10)
            assert reply["type"] == "error" and "objects or lists" in reply["message"]
    finally:
        srv.shutdown()
        srv.server_close()
    assert "Traceback" not in capsys.readouterr().err


@pytest.mark.parametrize("reply, words", [
    ({"commands": [[0.5, 0.0, 0.0]]}, "command time"),                 # to apply before this step (t = 1 s)
    ({"commands": [[1e308, 0.0, 0.0]]}, "command time"),
    ({"commands": [[1.0, 0.0, 0.0]] * 101}, "101 commands"),
    ({"latency": {"e2e": 1e308}}, "latency"),
    ({"latency": {"e2e": -0.1}}, "latency"),
    ({"objects": 1e308}, "object count"),
    ({"objects": -1}, "object count"),
    ({"objects": 2.5}, "fractional"),
    ({"events": [[1.0, "x", {}]] * 20_000}, "20000 events"),
    ({"events": [[-5.0, "x", {}]]}, "event time"),
    ({"events": [[1e6, "x", {}]]}, "event time"),
])
def test_absurd_peer_values_are_stack_failures(reply, words):
    with pytest.raises(StackError, match=words):
        _control({"type": "control", **reply}, 1.0, 0.01)


def test_bounded_peer_values_pass():
    command, commands, latency, objects, events = _control(
        {"type": "control", "command": [0.1, -1e308], "commands": [[1.0, 0.1, 2.0], [1.2, 0.0, 0.0]],
         "latency": {"e2e": 0.05}, "objects": 3, "events": [[1.0, "x", {}]] * MAX_EVENTS_PER_STEP}, 1.0, 0.01)
    # Command values are the vehicle's to clip, as in process (a bit flip in the stack makes the same).
    assert command == (0.1, -1e308) and commands[1] == (1.2, 0.0, 0.0) and latency == {"e2e": 0.05}
    assert objects == 3 and len(events) == MAX_EVENTS_PER_STEP


@pytest.mark.parametrize("address, words", [
    ("127.0.0.1:99999", "port 99999 is outside 1-65535"),
    ("127.0.0.1:0", "port 0"),
    ("::1:5555", "brackets"),
    ("[::1:5555", "not an IPv6 address"),
    ("[nope]:5555", "not an IPv6 address"),
    ("bad host:5555", "not a host name"),
    ("127.0.0.1:５５５５", "HOST:PORT"),
])
def test_addresses_that_cannot_be_used_are_refused(address, words):
    with pytest.raises(ValueError, match=words):
        parse_address(address)


def test_ipv6_loopback_is_parsed_without_brackets_and_served():
    assert parse_address("[::1]:5555") == ("::1", 5555) and is_loopback("::1")
    assert parse_address("localhost:1") == ("localhost", 1)
    if not socket.has_ipv6:
        pytest.skip("no IPv6 on this machine")
    try:
        srv = start_in_thread("[::1]:0")
    except OSError as exc:
        pytest.skip(f"cannot bind ::1 here: {exc}")
    try:
        host, port = parse_address(srv.address)
        with socket.create_connection((host, port), timeout=5) as s:
            send(s, {"type": "bogus"})
            reply, _ = recv(s, deadline=time.monotonic() + 5)
        assert reply["type"] == "error" and "unknown message type" in reply["message"]
    finally:
        srv.shutdown()
        srv.server_close()


def test_a_scenario_with_an_address_it_cannot_use_does_not_compile():
    from addt_dsl.compiler import compile_source

    source = """scenario addr {
  duration 1 s
  road r {
    line length 200 m
  }
  ego car on r lane -1 at 10 m speed 10 m/s {
    stack external address "%s" timeout 5 s
  }
}
"""
    for bad in ("127.0.0.1:99999", "::1:5555"):
        result = compile_source(source % bad, path="addr.addt")
        assert [d.code for d in result.diagnostics if d.severity == "error"] == ["E0204"], bad
    assert compile_source(source % "[::1]:5555", path="addr.addt").ok
