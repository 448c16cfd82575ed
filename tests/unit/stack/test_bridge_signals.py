"""Traffic lights and stop signs across the bridge (protocol 3): the hello that carries the
stop lines and stop signs on the ego's route, the step that carries each light's state, the
versions (older servers refuse a run that needs them with a clear error; older clients are
served, their stack knowing of no light), and the malformed fields the server refuses."""

import socket
import time

import pytest

from addt_dsl.compiler import compile_source
from addt_dsl.runtime.execute import execute
from addt_dsl.stack import bridge_server
from addt_dsl.stack.bridge import recv, send
from addt_dsl.stack.bridge_server import Limits, start_in_thread
from addt_dsl.sweep import expand
from tests.unit.stack.test_bridge_faults import _recording_remote

# A light at 40 m (green 0.5 s, yellow 0.5 s, then red) the ego, at 10 m and 10 m/s, must stop for.
SCENARIO = """
scenario remote_light {
  duration 2.5 s
  road r {
    line length 300 m
    lanes right 2 width 3.5 m
  }
  lights {
    signal s1 road r at 40 m
    controller main signals [s1] green 0.5 s yellow 0.5 s red 30 s
  }
  ego car on r lane -1 at 10 m speed 10 m/s {
    STACK
  }
  FAULTS
}
"""


def _spec(stack: str, faults: str = ""):
    result = compile_source(SCENARIO.replace("STACK", stack).replace("FAULTS", faults))
    assert result.ok, result.diagnostics
    return expand(result.plan).specs[0]


@pytest.fixture(scope="module")
def sent():
    """A real protocol-3 hello and the steps after it, as the client sends them."""
    control = {"type": "control", "command": [0.0, 0.0]}  # coasts
    address, got = _recording_remote([{"type": "ready"}] + [control] * 150 + [None])
    execute(_spec(f'stack external address "{address}" timeout 1 s'))
    steps = [m for m in got[1:] if m["type"] == "step"]
    assert len(steps) == 151
    return got[0], steps


def test_the_hello_carries_the_stop_lines_and_each_step_the_lights_states(sent):
    hello, steps = sent
    assert hello["protocol"] == 3 and hello["faults"] == [] and hello["duration_s"] == 2.5
    # The line at 40 m of the road, the ego's lane driving along +s: station 40 m.
    assert hello["stop_lines"] == [{"station_m": 40.0, "controller": "main"}]
    assert hello["signs"] == []
    # Green until 0.5 s, yellow until 1 s, then red (state codes 0, 1, 2), at each step's time.
    for step in steps:
        t = step["time_s"]
        want = 0.0 if t < 0.5 - 1e-9 else 1.0 if t < 1.0 - 1e-9 else 2.0
        assert step["lights"] == {"main": want}, t
    assert {s["lights"]["main"] for s in steps} == {0.0, 1.0, 2.0}


def test_a_run_without_lights_or_signs_says_hello_in_protocol_1_or_2():
    road = ("  lights {\n    signal s1 road r at 40 m\n"
            "    controller main signals [s1] green 0.5 s yellow 0.5 s red 30 s\n  }\n")
    assert road in SCENARIO
    for faults, protocol in (("", 1), ("faults {\n    at 1 s bitflip planner.state bit 0\n  }", 2)):
        source = SCENARIO.replace(road, "").replace("STACK", 'stack external address "ADDR" timeout 1 s')
        address, got = _recording_remote([None])
        result = compile_source(source.replace("ADDR", address).replace("FAULTS", faults))
        assert result.ok, result.diagnostics
        execute(expand(result.plan).specs[0])
        assert got[0]["protocol"] == protocol and "stop_lines" not in got[0] and "signs" not in got[0]


def test_a_faulted_run_with_a_light_through_the_server_equals_the_in_process_run(server):
    faults = "faults {\n    at 0.5 s bitflip planner.state bit 0\n  }"
    local = execute(_spec("stack bev", faults))
    remote = execute(_spec(f'stack external address "{server.address}" timeout 10 s', faults))
    assert remote.status == "ok", remote.error
    assert [e.detail["kind"] for e in remote.trace.events if e.kind == "fault"] == ["bitflip"]
    assert remote.digest == local.digest
    ego = remote.trace.actors["ego"]
    assert (ego.s + 0.5 * ego.length_m).max() <= 40.0  # held before the line


def test_a_server_that_speaks_only_protocols_1_and_2_refuses_with_a_clear_error(monkeypatch):
    monkeypatch.setattr(bridge_server, "PROTOCOLS", (1, 2))  # the server as it was
    srv = start_in_thread("127.0.0.1:0", Limits(idle_timeout_s=5.0))
    try:
        result = execute(_spec(f'stack external address "{srv.address}" timeout 5 s'))
    finally:
        srv.shutdown()
        srv.server_close()
    assert result.status == "detected"
    assert "protocol 3 not supported" in result.error  # the server's words
    assert "traffic lights (main)" in result.error and "need bridge protocol 3" in result.error


def _exchange(server, *messages):
    """Send each message and read its reply; the replies."""
    out = []
    with socket.create_connection(server.server_address[:2], timeout=5) as s:
        for m in messages:
            send(s, m)
            out.append(recv(s, deadline=time.monotonic() + 5)[0])
    return out


def test_older_clients_are_served_and_their_stack_knows_of_no_light(server, sent):
    hello, steps = sent
    old = {k: v for k, v in hello.items() if k not in ("stop_lines", "signs", "faults", "duration_s")}
    step = {**{k: v for k, v in steps[0].items() if k != "lights"}, "frames": []}  # (the recorder keeps no blobs)
    for protocol, extra in ((1, {}), (2, {"faults": [], "duration_s": 2.5})):
        ready, control = _exchange(server, {**old, **extra, "protocol": protocol}, step)
        assert ready["type"] == "ready" and control["type"] == "control", control
    # What the server's stack reads: no line and no sign from an older hello; the lines from a new one.
    assert bridge_server.RemoteContext({**old, "protocol": 1}).stop_line_ahead(0.0) is None
    assert bridge_server.RemoteContext({**old, "protocol": 1}).stop_sign_ahead(0.0) is None
    ctx = bridge_server.RemoteContext(hello)
    ctx.light_states = {"main": 2.0}
    assert ctx.stop_line_ahead(0.0) == (40.0, 2.0)
    # Stop lines in an older protocol's hello are refused rather than half-read.
    (reply,) = _exchange(server, {**hello, "protocol": 2})
    assert reply["type"] == "error" and "need protocol 3" in reply["message"]


def test_the_server_answers_stop_lines_and_signs_as_the_in_process_context():
    from addt_dsl.runtime.lights import StopStation, next_stop
    from addt_dsl.runtime.signs import next_sign

    ctx = bridge_server.RemoteContext.__new__(bridge_server.RemoteContext)
    ctx.ego_length_m = 4.0
    lines = [(120.0, "b"), (60.0, "a"), (120.0, "a")]  # two controllers on one line, sent unordered
    ctx.stop_lines = sorted((StopStation(u, c) for u, c in lines), key=lambda st: (st.u, st.controller))
    ctx.sign_lines = [30.0, 90.0]
    ctx.light_states = {"a": 0.0, "b": 2.0}
    stations = sorted((StopStation(u, c) for u, c in lines), key=lambda st: (st.u, st.controller))
    for s in (0.0, 57.0, 58.4, 58.6, 100.0, 117.9, 118.4, 118.6, 200.0):
        front = s + 2.0
        assert ctx.stop_line_ahead(s) == next_stop(stations, front, ctx.light_states.__getitem__)
        assert ctx.stop_sign_ahead(s, (30.0,)) == next_sign([30.0, 90.0], front, (30.0,))
    assert ctx.stop_line_ahead(100.0) == (120.0, 2.0)  # the line's most restrictive light
    assert ctx.stop_sign_ahead(0.0) == 30.0 and ctx.stop_sign_ahead(0.0, (30.0,)) == 90.0


def test_the_server_reads_each_junctions_rule_from_the_signs_kinds(server, sent):
    from addt_dsl.runtime.lights import StopStation
    from addt_dsl.runtime.signs import junction_rule

    hello = {**sent[0], "signs": [{"station_m": 150.0, "kind": "yield"}, {"station_m": 20.0, "kind": "priority"},
                                  {"station_m": 20.0, "kind": "stop"}]}
    ctx = bridge_server.RemoteContext(hello)
    assert ctx.sign_lines == [20.0]  # the stop signs' lines: what `stop_sign_ahead` reads
    ctx.junctions = [(30.0, 45.0, 0.0, 0.0), (160.0, 175.0, 0.0, 0.0)]  # (entry, exit, centre x, y)
    rules = [StopStation(20.0, "priority"), StopStation(20.0, "stop"), StopStation(150.0, "yield")]
    for s in (0.0, 25.0, 44.0, 50.0, 150.0, 172.0, 200.0):
        assert ctx.junction_rule(s) == junction_rule(rules, ctx.junctions, s + 0.5 * ctx.ego_length_m)
    # A stop sign outranks a priority sign on one approach (`SIGN_KINDS`' order); the next
    # junction's approach has a yield sign; past the last junction no rule.
    assert [ctx.junction_rule(s) for s in (0.0, 50.0, 200.0)] == ["stop", "yield", None]
    (reply,) = _exchange(server, hello)
    assert reply["type"] == "ready", reply


@pytest.mark.parametrize("over, words", [
    ({"stop_lines": "main"}, "'stop_lines' must be a list"),
    ({"signs": None}, "'signs' must be a list"),
    ({"stop_lines": [{"station_m": 40.0, "controller": "x"}] * 10_001}, "at most 10000"),
    ({"stop_lines": [{"station_m": float("nan"), "controller": "main"}]}, "finite number"),
    ({"stop_lines": [{"station_m": True, "controller": "main"}]}, "finite number"),
    ({"stop_lines": [{"station_m": "40", "controller": "main"}]}, "finite number"),
    ({"stop_lines": [{"station_m": 40.0}]}, "'controller'"),
    ({"stop_lines": [{"station_m": 40.0, "controller": ""}]}, "'controller'"),
    ({"stop_lines": [[40.0, "main"]]}, "must be an object"),
    ({"signs": [{"station_m": float("inf"), "kind": "stop"}]}, "finite number"),
    ({"signs": [{"station_m": 80.0}]}, "'kind' must be one of stop, yield, priority, priority_road, priority_road_end"),
    ({"signs": [{"station_m": 80.0, "kind": "give_way"}]}, "'kind' must be one of"),
    ({"signs": [{"station_m": 80.0, "kind": ["stop"]}]}, "'kind' must be one of"),
])
def test_bad_signals_in_a_hello_are_refused(server, sent, over, words):
    (reply,) = _exchange(server, {**sent[0], **over})
    assert reply["type"] == "error" and words in reply["message"], reply


@pytest.mark.parametrize("lights", [None, {}, {"main": 3}, {"main": True}, {"main": "red"}, {"main": [2]},
                                    {"other": 2}, "red"])
def test_a_step_without_each_lights_state_is_refused(server, sent, lights):
    hello, steps = sent
    step = {**{k: v for k, v in steps[0].items() if k != "lights"}, "frames": []}  # (the recorder keeps no blobs)
    if lights is not None:
        step["lights"] = lights
    ready, reply = _exchange(server, hello, step)
    assert ready["type"] == "ready" and reply["type"] == "error" and "'lights'" in reply["message"], reply
