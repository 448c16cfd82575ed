"""bitflip, stuck, random_value on scalar sites and nodes; the schedule's binding."""

import math
import struct

import numpy as np
import pytest
from tests.unit.runtime.faults.faultkit import bound, schedule
from hypothesis import given
from hypothesis import strategies as st

from addt_dsl.runtime.faults import flip_float64_bit

NODES = {"control": ("control.steer", "control.accel", "control.integral"), "planner": ("planner.speed",)}


def _bits(x: float) -> int:
    return struct.unpack("<Q", struct.pack("<d", x))[0]


@given(st.floats(allow_nan=False), st.integers(0, 63))
def test_flip_is_an_involution_that_changes_exactly_one_bit(x, bit):
    y = flip_float64_bit(x, bit)
    assert bin(_bits(x) ^ _bits(y)).count("1") == 1
    assert _bits(flip_float64_bit(y, bit)) == _bits(x)


@given(st.floats(min_value=-0.999, max_value=0.999), st.integers(0, 63))
def test_one_flip_of_a_value_below_one_stays_finite(x, bit):
    # Why a single flip in `control.steer` (|steer| <= 0.5) never makes the watchdog fire:
    # its exponent is at most 0x3FE, one flip reaches 0x7FE at most, never 0x7FF (inf/NaN).
    assert math.isfinite(flip_float64_bit(x, bit))


def _feed(sched, site, times, value=1.5):
    out = []
    for t in times:
        v = value
        for k in sched.for_target(site):
            v = k.on_value(site, v, t)
        out.append(v)
    return out


def test_count_flips_at_seeded_instants_inside_the_window():
    sched, kind, events = bound("bitflip", target="control.steer", nodes=NODES, count=4, start=2.0, end=6.0)
    assert len(kind.times) == 4 and all(2.0 <= t <= 6.0 for t in kind.times)
    times = np.arange(0, 10, 0.01)
    out = _feed(sched, "control.steer", times)
    flipped = [t for t, v in zip(times, out) if v != 1.5]
    assert len(events) == 4
    assert [e.time_s for e in events] == flipped
    for e, t_flip in zip(events, kind.times):
        assert t_flip <= e.time_s < t_flip + 0.01
        d = e.detail
        assert d["location"] == "control.steer" and d["before"] == 1.5
        assert d["value"] == flip_float64_bit(1.5, d["bit"])


def test_at_puts_every_flip_on_the_first_value_at_the_instant():
    sched, kind, events = bound("bitflip", target="control.accel", nodes=NODES, count=3, start=1.0, end=1.0)
    out = _feed(sched, "control.accel", [0.99, 1.0, 1.01])
    assert out[0] == 1.5 and out[2] == 1.5 and len(events) == 3
    assert all(e.time_s == 1.0 for e in events)


@pytest.mark.parametrize("field, lo, hi", [("sign", 63, 64), ("exponent", 52, 63), ("mantissa", 0, 52)])
def test_field_restricts_the_bit(field, lo, hi):
    sched, _, events = bound("bitflip", target="control.steer", nodes=NODES, count=50, start=0.0, end=1.0,
                             field=field)
    _feed(sched, "control.steer", np.arange(0, 1.01, 0.01))
    bits = {e.detail["bit"] for e in events}
    assert len(events) == 50 and bits <= set(range(lo, hi)) and len(bits) > 1 or hi - lo == 1


def test_fixed_bit_index():
    sched, _, events = bound("bitflip", target="control.steer", nodes=NODES, bit=62, start=0.5, end=0.5)
    (out,) = _feed(sched, "control.steer", [0.5])
    assert _bits(out) == _bits(1.5) ^ (1 << 62)
    assert math.isnan(events[0].detail["value"])  # 1.5 with bit 62 set: exponent all ones, mantissa != 0


def test_a_node_target_spreads_flips_over_the_node_s_sites():
    sched, kind, events = bound("bitflip", target="control", nodes=NODES, count=300, start=0.0, end=3.0, seed=4)
    times = np.arange(0, 3.01, 0.01)
    for t in times:
        for site in NODES["control"]:
            for k in sched.for_target(site):
                k.on_value(site, 0.25, t)
    sites = [e.detail["location"] for e in events]
    assert len(sites) == 300 and set(sites) == set(NODES["control"])
    assert min(sites.count(s) for s in NODES["control"]) > 70  # ~100 each
    assert not sched.for_target("planner.speed")


def test_binding_rejects_a_site_the_stack_does_not_have():
    with pytest.raises(ValueError, match="does not have"):
        bound("bitflip", target="perception.backbone_0", nodes=NODES)


def test_bit_index_beyond_the_value_is_an_error():
    sched, kind, _ = bound("bitflip", target="control.steer", nodes=NODES, bit=40, start=0.0, end=0.0)
    with pytest.raises(ValueError, match="does not exist"):
        kind._bit_in(0, 32, 32)


def test_stuck_and_random_value_record_location_and_injected_value():
    sched, events = schedule({"kind": "stuck", "target": "planner.speed", "value": 0.0, "start": 1.0, "end": 2.0},
                             {"kind": "random_value", "target": "control.steer", "low": -0.2, "high": 0.2,
                              "start": 0.0, "end": 0.5})
    stuck, rnd = sched.kinds
    assert stuck.on_value("planner.speed", 20.0, 0.5) == 20.0
    assert stuck.on_value("planner.speed", 20.0, 1.5) == 0.0
    assert stuck.on_value("planner.speed", 0.0, 1.6) == 0.0  # no change, nothing recorded
    vals = [rnd.on_value("control.steer", 0.0, t) for t in np.arange(0, 1, 0.1)]
    assert all(-0.2 <= v <= 0.2 for v in vals[:6]) and vals[6:] == [0.0] * 4
    stuck_ev = [e.detail for e in events if e.detail["kind"] == "stuck"]
    assert stuck_ev == [{"index": 0, "kind": "stuck", "target": "planner.speed", "location": "planner.speed",
                         "value": 0.0, "before": 20.0}]
    (series,) = [e for e in events if e.detail["kind"] == "random_value"]  # one event per site
    assert series.time_s == 0.0 and series.detail["location"] == "control.steer"
    assert series.detail["value"] == vals[:6] and series.detail["before"] == [0.0] * 6
    assert series.detail["times"] == pytest.approx(list(np.arange(0, 0.6, 0.1)))


def test_random_value_on_a_node_keeps_one_series_per_site_and_every_injection_in_the_trace():
    from addt_dsl.runtime.trace import Trace, injection_count

    sched, kind, events = bound("random_value", nodes=NODES, target="control", low=-1.0, high=1.0,
                                start=0.0, end=0.05)
    injected = []
    for k in range(8):  # control ticks at 100 Hz: steer, then accel, then the integral
        t = k * 0.01
        for site, true in (("control.steer", 0.1 * k), ("control.accel", -0.2 * k)):
            for f in sched.for_target(site):
                out = f.on_value(site, true, t)
                if out != true:
                    injected.append((t, site, out, true))
    assert len(injected) == 12  # 6 ticks in [0, 0.05] x 2 sites
    assert [e.detail["location"] for e in events] == ["control.steer", "control.accel"]
    assert [injection_count(e) for e in events] == [6, 6]
    trace = Trace(0.01, np.zeros(1), {}, {}, events)
    rows = trace.fault_injections()
    assert trace.injection_count() == 12
    assert sorted((r["time_s"], r["location"], r["value"], r["before"]) for r in rows) == sorted(injected)
    assert all(r["kind"] == "random_value" and r["target"] == "control" and r["index"] == 0 for r in rows)


def test_the_digest_sees_every_value_of_a_series():
    from addt_dsl.runtime.trace import Trace

    sched, events = schedule({"kind": "random_value", "target": "control.steer", "start": 0.0, "end": 1.0})
    for k in range(50):
        sched.kinds[0].on_value("control.steer", 0.0, k * 0.01)
    trace = Trace(0.01, np.zeros(1), {}, {}, events)
    before = trace.digest()
    assert trace.digest() == before
    events[0].detail["value"][37] = math.nextafter(events[0].detail["value"][37], 2.0)  # one ulp
    assert trace.digest() != before


def test_spike_and_slow_add_latency_in_their_window():
    sched, events = schedule({"kind": "spike", "target": "planner", "by": 0.2, "start": 1.0, "end": 2.0},
                             {"kind": "slow", "target": "perception", "factor": 3.0})
    spike, slow = sched.kinds
    assert spike.extra_latency("planner", 0.5, 0.01) == 0.0
    assert spike.extra_latency("planner", 1.5, 0.01) == 0.2
    assert slow.extra_latency("perception", 0.0, 0.05) == pytest.approx(0.1)
    assert [(e.detail["location"], e.detail["value"]) for e in events] == [("planner", 0.2),
                                                                          ("perception", pytest.approx(0.1))]


def test_every_injection_records_the_same_fields():
    sched, events = schedule({"kind": "drop", "rate": 1.0}, {"kind": "delay", "by": 0.1},
                             {"kind": "stuck", "target": "control.steer", "value": 0.1},
                             {"kind": "spike", "target": "control", "by": 0.1})
    from tests.unit.runtime.faults.faultkit import lidar_frame

    sched.kinds[0].on_frame(lidar_frame(3), 0.0)
    sched.kinds[1].on_frame(lidar_frame(3), 0.0)
    sched.kinds[2].on_value("control.steer", 0.0, 0.0)
    sched.kinds[3].extra_latency("control", 0.0, 0.001)
    assert len(events) == 4
    for e in events:
        assert {"index", "kind", "target", "location", "value"} <= set(e.detail)


def test_schedule_timers_run_in_time_then_setting_order_at_their_step():
    """`Binding.at` timers: the loop calls `wake` when a step reaches `next_wake_s`; due
    timers run in time order (ties in the order set), a timer set by a callback for a time
    already reached runs in the same wake, and `next_wake_s` is inf once none is left."""
    sched, _ = schedule()
    calls = []
    sched.at(0.5, lambda: calls.append("b"))
    sched.at(0.2, lambda: calls.append("a"))
    sched.at(0.5, lambda: (calls.append("c"), sched.at(0.3, lambda: calls.append("d"))))
    sched.at(2.0, lambda: calls.append("e"))
    assert sched.next_wake_s == 0.2
    sched.wake(0.1)
    assert calls == [] and sched.next_wake_s == 0.2
    sched.wake(0.2)
    assert calls == ["a"] and sched.next_wake_s == 0.5
    sched.wake(0.5 - 1e-13)  # within the loop's tolerance of the instant
    assert calls == ["a", "b", "c", "d"] and sched.next_wake_s == 2.0
    sched.wake(3.0)
    assert calls == ["a", "b", "c", "d", "e"] and sched.next_wake_s == math.inf
