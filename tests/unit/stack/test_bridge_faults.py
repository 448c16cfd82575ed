"""Stack-internal faults across the bridge (protocol 2): the hello that carries them, the
server that applies them with the in-process fault machinery and reports each injection,
and every way of refusing them (old servers, stacks that ignore them, malformed entries)."""

import socket
import threading
import time
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from addt_dsl.compiler import compile_source
from addt_dsl.plan import ConcreteFault
from addt_dsl.runtime.execute import execute
from addt_dsl.runtime.trace import SERIES_COLUMNS, Event
from addt_dsl.stack.bev import StackError
from addt_dsl.stack.bridge import _grow_series, decode, encode, recv, send
from addt_dsl.stack.bridge_server import _new_events, _series

SCENARIO = """
scenario remote_faults {
  duration 2 s
  road r {
    line length 300 m
    lanes right 2 width 3.5 m
  }
  ego car on r lane -1 at 10 m speed 15 m/s {
    STACK
    sensor lidar rate 10 Hz
  }
  agent lead car on r lane -1 at 40 m speed 10 m/s
  faults {
FAULTS
  }
}
"""
# A state site, a series fault (one event whose columns grow), a node latency fault and
# a sensor fault (which stays in the simulator).
FAULTS = """    at 0.5 s bitflip planner.state bit 0
    during [0.3 s, 0.9 s] bitflip tracker.tracks count 2 field exponent
    during [0.5 s, 1.5 s] random_value control.steer low -0.001 high 0.001
    at 1.2 s bitflip control.integral bit 62
    during [1 s, 1.5 s] spike perception by 50 ms
    during [0 s, 2 s] drop lidar rate 20 %"""


def _spec(stack: str, faults: str = FAULTS):
    from addt_dsl.sweep import expand

    result = compile_source(SCENARIO.replace("STACK", stack).replace("FAULTS", faults))
    assert result.ok, result.diagnostics
    return expand(result.plan).specs[0]


@pytest.fixture(autouse=True)
def _no_tracebacks(capsys):
    yield
    assert "Traceback" not in capsys.readouterr().err


def test_faulted_run_through_the_reference_server_equals_the_in_process_run(server):
    local = execute(_spec("stack bev"))
    remote = execute(_spec(f'stack external address "{server.address}" timeout 10 s'))
    assert remote.status == "ok", remote.error
    kinds = {e.detail["kind"] for e in remote.trace.events if e.kind == "fault"}
    assert kinds == {"bitflip", "random_value", "spike", "drop"}  # every fault injected
    series = [e for e in remote.trace.events if e.kind == "fault" and "times" in e.detail]
    assert len(series) == 1 and len(series[0].detail["times"]) > 50  # grew over many replies
    # (repr: the integrator flip makes a NaN, which equals nothing)
    assert repr(remote.trace.fault_injections()) == repr(local.trace.fault_injections())
    assert remote.digest == local.digest


def _recording_remote(answers):
    """A remote that records the messages it gets and answers them from `answers`
    (a message or None: no answer), then closes."""
    listener = socket.create_server(("127.0.0.1", 0))
    got = []

    def serve():
        conn, _ = listener.accept()
        with conn:
            for answer in answers:
                try:
                    got.append(recv(conn, deadline=time.monotonic() + 5)[0])
                except (OSError, ValueError):
                    break
                if answer is not None:
                    send(conn, answer)
        listener.close()

    threading.Thread(target=serve, daemon=True).start()
    return "127.0.0.1:%d" % listener.getsockname()[1], got


CONTROL = {"type": "control", "command": [0.0, 0.0], "commands": [[0.0, 0.0, 0.0]]}


def test_hello_carries_the_stack_internal_faults_only_when_the_run_has_them():
    address, got = _recording_remote([{"type": "ready"}, CONTROL, None])
    result = execute(_spec(f'stack external address "{address}" timeout 1 s', faults="    at 1 s drop lidar"))
    assert result.status == "detected" and [m["type"] for m in got] == ["hello", "step", "step"]  # ready was enough
    assert got[0]["protocol"] == 1 and "faults" not in got[0]  # a protocol-1 server serves it

    address, got = _recording_remote([None])  # never answers: the client times out
    spec = _spec(f'stack external address "{address}" timeout 1 s')
    execute(spec)
    hello = got[0]
    assert hello["protocol"] == 2 and hello["duration_s"] == 2.0
    sent = [ConcreteFault.model_validate(f) for f in hello["faults"]]
    # Every fault but the sensor's, exactly as the RunSpec resolved it (index, seed, window).
    assert sent == [f for f in spec.faults if f.kind != "drop"]
    assert "sites" not in hello["stack"] and "address" not in hello["stack"]


@pytest.mark.parametrize("ready, words", [
    # A stack that says ready and ignores the faults (protocol 1, like docs/bridge.md's
    # minimal stack) would let the run pass as if faulted: it is detected.
    ({"type": "ready"}, "did not confirm"),
    ({"type": "ready", "protocol": 2, "faults": [0]}, "did not confirm"),
    ({"type": "ready", "protocol": 2, "faults": [0, "1", None, 2.0, [3]]}, "did not confirm"),
    # What a protocol-1-only server answers a protocol-2 hello.
    ({"type": "error", "message": "ValueError: protocol 2 not supported (this is 1)"}, "need bridge protocol 2"),
])
def test_a_remote_that_does_not_take_the_faults_ends_the_run_detected(ready, words):
    address, _ = _recording_remote([ready, None])
    result = execute(_spec(f'stack external address "{address}" timeout 5 s'))
    assert result.status == "detected" and words in result.error
    assert "bitflip planner.state" in result.error  # says which faults


def test_the_server_confirms_the_faults_it_applies_and_serves_protocol_1(server):
    address, got = _recording_remote([None])
    execute(_spec(f'stack external address "{address}" timeout 1 s'))
    hello = got[0]
    with socket.create_connection(server.server_address[:2], timeout=5) as s:
        send(s, hello)
        ready = recv(s, deadline=time.monotonic() + 5)[0]
    assert ready["type"] == "ready" and ready["protocol"] == 2 and ready["faults"] == [0, 1, 2, 3, 4]
    old = {k: v for k, v in hello.items() if k not in ("faults", "duration_s")}
    with socket.create_connection(server.server_address[:2], timeout=5) as s:
        send(s, {**old, "protocol": 1})
        ready = recv(s, deadline=time.monotonic() + 5)[0]
    assert ready["type"] == "ready" and "faults" not in ready


@pytest.fixture(scope="module")
def hello():
    """A real protocol-2 hello, as the client sends it."""
    address, got = _recording_remote([None])
    execute(_spec(f'stack external address "{address}" timeout 1 s', faults="    at 1 s bitflip planner.state"))
    return got[0]


def _fault(**over):
    f = {"index": 0, "kind": "bitflip", "target": "planner.state", "start_s": 1.0, "end_s": 1.0,
         "settings": {"bit": 3}, "seed": 7}
    f.update(over)
    return f


@pytest.mark.parametrize("faults, over, words", [
    ([_fault()], {"protocol": 1}, "needs protocol 2"),
    ([_fault(kind="drop", target="lidar")], {}, "not a stack-internal fault kind"),
    ([_fault(kind="meltdown")], {}, "not a stack-internal fault kind"),
    ([_fault(target="planner.memory")], {}, "does not have"),
    ([_fault(settings={"count": 10**9})], {}, "count"),
    ([_fault(settings={"bit": 2.5})], {}, "integer"),
    ([_fault(settings={"wattage": 1})], {}, "wattage"),
    ([_fault(settings={"field": "rainbow"})], {}, "field"),
    ([_fault(start_s=float("nan"))], {}, "window"),
    ([_fault(end_s=0.5)], {}, "window"),
    ([_fault(seed=-1)], {}, "seed"),
    ([_fault(), _fault()], {}, "twice"),
    ([_fault(index="x")], {}, "index"),
    ([_fault()] * 1001, {}, "at most"),
    ("all of them", {}, "list"),
    ([_fault()], {"duration_s": -1}, "duration_s"),
])
def test_bad_faults_in_a_hello_are_refused(server, hello, faults, over, words):
    with socket.create_connection(server.server_address[:2], timeout=5) as s:
        send(s, {**hello, "faults": faults, **over})
        reply = recv(s, deadline=time.monotonic() + 5)[0]
    assert reply["type"] == "error" and words in reply["message"], reply


def test_a_good_fault_in_the_same_hello_is_taken(server, hello):
    with socket.create_connection(server.server_address[:2], timeout=5) as s:
        send(s, {**hello, "faults": [_fault(index=4)]})
        reply = recv(s, deadline=time.monotonic() + 5)[0]
    assert reply == {"type": "ready", "stack": "bev", "nodes": reply["nodes"], "protocol": 2, "faults": [4]}


def _series_event():
    return Event(1.0, "fault", {"index": 0, "kind": "random_value", "target": "control.steer",
                                "location": "control.steer", "times": [], "value": [], "before": []})


def test_series_entries_extend_the_event_they_name_bit_for_bit():
    events = [Event(0.5, "detections", {}), _series_event()]
    nan = np.frombuffer(np.uint64(0x7FF0_0000_0000_0001).tobytes(), dtype="<f8")  # a NaN with a payload
    blobs = {"t": np.array([1.0, 1.01]), "v": np.array([0.1, -0.2]), "b": np.concatenate([nan, [0.3]])}
    _grow_series([[1, {"times": "t", "value": "v", "before": "b"}]], blobs, events)
    _grow_series([[1, {"times": "t", "value": "v", "before": "b"}]], blobs, events)
    d = events[1].detail
    assert d["times"] == [1.0, 1.01, 1.0, 1.01] and d["value"] == [0.1, -0.2, 0.1, -0.2]
    assert np.asarray(d["before"][:1]).tobytes() == nan.tobytes()


@pytest.mark.parametrize("series, blobs", [
    ([[5, {"times": "t", "value": "t", "before": "t"}]], {"t": np.zeros(1)}),  # no such event
    ([[0, {"times": "t", "value": "t", "before": "t"}]], {"t": np.zeros(1)}),  # not a series
    ([[1, {"times": "t", "value": "t", "before": "u"}]], {"t": np.zeros(1)}),  # missing blob
    ([[1, {"times": "t", "value": "t", "before": "u"}]], {"t": np.zeros(1), "u": np.zeros(2)}),  # lengths
    ([[1, {"times": "t", "value": "t", "before": "t"}]], {"t": np.zeros((1, 1))}),  # not a column
    ([[True, {}]], {}),
    ([["1"]], {}),
    ("nonsense", {}),
])
def test_malformed_series_entries_are_stack_failures(series, blobs):
    with pytest.raises(StackError):
        _grow_series(series, blobs, [Event(0.5, "detections", {}), _series_event()])


def test_a_hand_built_run_with_faults_on_a_stack_without_sites_is_detected():
    # The compiler refuses this (E0109); a RunSpec edited by hand ends detected, not crashed.
    spec = _spec('stack external address "127.0.0.1:9" timeout 1 s')
    ego = spec.plan.ego
    stack = ego.stack.model_copy(update={"settings": {**ego.stack.settings, "sites": "none"}})
    plan = spec.plan.model_copy(update={"ego": ego.model_copy(update={"stack": stack})})
    result = execute(spec.model_copy(update={"plan": plan}))
    assert result.status == "detected" and "declares no fault sites" in result.error


# Per reply: new plain events, new series events, and entries added to the series so far.
steps = st.lists(st.tuples(st.integers(0, 2), st.integers(0, 1),
                           st.lists(st.lists(st.floats(allow_nan=True, width=64), max_size=4), max_size=3)),
                 min_size=1, max_size=6)


@settings(max_examples=60, deadline=None)
@given(steps)
def test_series_events_cross_the_wire_bit_for_bit(script):
    """Whatever the server's events do between replies (new events, new series, entries
    appended to earlier series), the client's copies end equal, columns byte for byte."""
    server = SimpleNamespace(events=[], sent=0, series_sent={})
    client: list = []
    for plain, new_series, growth in script:
        for _ in range(plain):
            server.events.append(Event(0.1 * len(server.events), "detections", {"objects": []}))
        for _ in range(new_series):
            server.events.append(_series_event())
        open_series = [e for e in server.events if "times" in e.detail]
        for e, values in zip(open_series, growth):
            for v in values:
                for c in SERIES_COLUMNS:
                    e.detail[c].append(v)
        reply, blobs = encode_reply(server)
        header, got = decode(encode(reply, blobs)[4:])
        client.extend(Event(t, kind, detail) for t, kind, detail in header["events"])
        if "series" in header:
            _grow_series(header["series"], got, client)
    assert [(e.time_s, e.kind) for e in client] == [(e.time_s, e.kind) for e in server.events]
    for mine, theirs in zip(client, server.events):
        for c in SERIES_COLUMNS if "times" in theirs.detail else ():
            assert np.asarray(mine.detail[c], dtype="<f8").tobytes() == np.asarray(theirs.detail[c], "<f8").tobytes()


def encode_reply(server):
    reply = {"type": "control", "events": _new_events(server)}
    series, blobs = _series(server)
    if series:
        reply["series"] = series
    return reply, blobs
