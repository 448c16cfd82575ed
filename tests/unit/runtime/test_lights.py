"""Traffic lights: phase programs as pure functions of time, stop lines from OpenDRIVE
signals, and the stopping rule agents follow."""

from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from addt_dsl.runtime.lights import (COMFORT_DECEL, GREEN, PAST_M, RED, REACH_M, YELLOW, LightsRuntime, Program,
                                     StopStation, governs_vehicles, next_stop, state_at, stations_on, stop_accel,
                                     stop_lines)
from addt_dsl.road import build_road, line, load_xodr, parse_xodr

MAPS = Path(__file__).resolve().parents[3] / "examples" / "maps"

durations = st.floats(min_value=0.1, max_value=60.0, allow_nan=False)


@settings(max_examples=200, deadline=None)
@given(durations, durations, durations, st.floats(min_value=0.0, max_value=100.0), st.floats(0.0, 500.0))
def test_program_is_periodic_and_follows_its_phases(green, yellow, red, offset, t):
    p = Program(green, yellow, red, offset)
    phase = (t - offset) % p.cycle_s
    want = GREEN if phase < green else YELLOW if phase < green + yellow else RED
    assert p.state(t) == want
    # The array form agrees with the scalar form, and a cycle later the state is the same
    # (away from a phase boundary, where rounding of t + cycle may move it).
    ts = np.array([t, t + p.cycle_s])
    if min(abs(phase - b) for b in (0.0, green, green + yellow, p.cycle_s)) > 1e-6:
        assert list(p.state(ts)) == [want, want]


def test_changes_override_the_program_until_it_is_resumed():
    p = Program(10.0, 3.0, 10.0)
    changes = [(4.0, "red"), (6.0, "yellow"), (8.0, "program")]
    t = np.array([0.0, 3.99, 4.0, 5.0, 6.0, 7.9, 8.0, 12.0, 14.0])
    assert list(state_at(p, changes, t)) == [GREEN, GREEN, RED, RED, YELLOW, YELLOW, GREEN, YELLOW, RED]
    assert state_at(p, [], 11.0) == YELLOW


def test_signals_of_the_traffic_light_map_give_stop_lines_for_their_lanes():
    net = load_xodr(MAPS / "fabriksgatan_traffic_lights.xodr")
    lines = stop_lines(net, "west", ["1", "2", "3"])
    # All three face +s traffic on road 3 (right-hand traffic: lane -1), but only signal 1
    # (type 1000001) is a vehicle light; 2 and 3 (type 1000002) are pedestrian lights,
    # which govern the crossing and make no stop line for vehicles.
    assert [net.signal(i)[1].type for i in ("1", "2", "3")] == ["1000001", "1000002", "1000002"]
    assert {(ln.signal, ln.road_id, ln.s, ln.direction, ln.lanes) for ln in lines} == {("1", "3", 109.0, 1, (-1,))}
    assert stop_lines(net, "walkers", ["2", "3"]) == []
    assert net.signal("2")[1].validity == (-1, 1)
    assert stop_lines(net, "west", ["404"]) == []


def test_which_signal_types_hold_vehicles():
    assert governs_vehicles("1000001") and governs_vehicles("1000011") and governs_vehicles("")
    assert not governs_vehicles("1000002")


def test_lights_on_one_line_hold_by_the_most_restrictive_whatever_their_order():
    lights = LightsRuntime({"a": Program(5.0, 1.0, 10.0), "b": Program(0.0, 0.0, 10.0)})  # a green, b red
    one = [StopStation(50.0, "a"), StopStation(50.0, "b")]
    for stations in (one, one[::-1]):
        assert next_stop(stations, 30.0, lambda c: lights.state(c, 1.0)) == (50.0, RED)
        assert lights.red_margin("x", 30.0, stations, 1.0) == 20.0
    later = [StopStation(50.0, "a"), StopStation(70.0, "b")]
    assert next_stop(later, 30.0, lambda c: lights.state(c, 1.0)) == (50.0, GREEN)
    assert next_stop(later, 60.0, lambda c: lights.state(c, 1.0)) == (70.0, RED)
    assert next_stop(later, 80.0, lambda c: lights.state(c, 1.0)) is None


def test_red_margin_of_a_line_with_two_controllers_does_not_depend_on_their_order():
    # Before it, `a` is red and `b` green; it crosses once `b` turned red too: a violation,
    # in either order of the stations (the armed state is kept per controller).
    lights = LightsRuntime({"a": Program(0.0, 0.0, 100.0), "b": Program(2.0, 0.0, 100.0)})
    for stations in ([StopStation(50.0, "a"), StopStation(50.0, "b")],
                     [StopStation(50.0, "b"), StopStation(50.0, "a")]):
        lights._armed.clear()
        assert lights.red_margin("x", 45.0, stations, 1.0) == 5.0
        assert lights.red_margin("x", 52.0, stations, 3.0) == -2.0


def test_controllers_are_read_from_opendrive():
    text = (MAPS / "fabriksgatan_traffic_lights.xodr").read_text()
    text = text.replace("</OpenDRIVE>", '<controller id="7" name="west"><control signalId="1" type="0"/>'
                        '<control signalId="3" type="0"/></controller></OpenDRIVE>')
    net = parse_xodr(text)
    assert net.controllers["7"].name == "west" and net.controllers["7"].signal_ids == ("1", "3")


def test_inline_signals_govern_the_lanes_given_or_every_lane_along_s():
    net = build_road("r", [line(200.0)], left_lanes=1, right_lanes=2, lane_width_m=3.5)
    (only,) = stop_lines(net, "c", ["s1"], {"s1": ("r", 80.0, (-2,))})
    assert (only.road_id, only.s, only.direction, only.lanes) == ("r", 80.0, 1, (-2,))
    (both,) = stop_lines(net, "c", ["s2"], {"s2": ("r", 80.0, ())})
    assert set(both.lanes) == {-1, -2}


class _Leg:
    def __init__(self, road_id, direction, s_from, s_to, lane):
        self.road_id, self.direction, self.s_from, self.s_to, self.lane = road_id, direction, s_from, s_to, lane


def test_stations_on_a_route_only_for_lines_on_its_legs_and_lanes():
    net = load_xodr(MAPS / "fabriksgatan_traffic_lights.xodr")
    lines = stop_lines(net, "west", ["1"]) + stop_lines(net, "east", ["1"]) + stop_lines(net, "west", ["1"])
    legs = [_Leg("3", 1, 50.0, 114.3, -1), _Leg("13", 1, 0.0, 14.9, -1)]
    got = stations_on(lines, legs, lambda road_id, s: s - 50.0)  # the route starts at s = 50 m on road 3
    # One station per controller on the line, in (station, controller) order, duplicates once.
    assert got == [StopStation(59.0, "east"), StopStation(59.0, "west")]
    assert stations_on(lines, [_Leg("3", -1, 114.3, 0.0, 1)], lambda r, s: s) == []  # the other direction
    assert stations_on(lines, [_Leg("3", 1, 0.0, 100.0, -1)], lambda r, s: s) == []  # ends before the lines


def _stop_distance(speed, dist, state, dt=0.01):
    """Where an agent driving at `speed` towards a line `dist` ahead stops (front - line) [m]."""
    s, v = 0.0, speed
    for _ in range(10000):
        a = stop_accel(v, dist - s, state)
        a = 0.0 if a is None else a
        v = max(0.0, v + a * dt)
        s += v * dt
        if v < 1e-3:
            break
    return s - dist, v


@settings(max_examples=60, deadline=None)
@given(st.floats(min_value=1.0, max_value=20.0), st.floats(min_value=20.0, max_value=99.0))
def test_an_agent_stops_before_a_red_line(speed, dist):
    assume(dist > speed * speed / (2.0 * COMFORT_DECEL) + 2.0)  # seen in time (else it brakes at 8 m/s^2)
    past, v = _stop_distance(speed, dist, RED)
    assert v < 1e-3 and -1.5 <= past <= 0.0


def test_green_and_too_late_yellow_do_not_hold_an_agent():
    assert stop_accel(10.0, 30.0, GREEN) is None
    assert stop_accel(15.0, 10.0, YELLOW) is None  # needs 11 m/s^2: it goes on
    assert stop_accel(10.0, 5.0, RED) == -8.0  # red: as hard as the stop allows
    assert stop_accel(10.0, REACH_M + 1.0, RED) is None


def test_red_margin_is_negative_only_for_a_line_crossed_at_red():
    lights = LightsRuntime({"c": Program(5.0, 1.0, 10.0)})
    stations = [StopStation(50.0, "c")]
    # Crossing at green, then being past the line when it turns red: no violation.
    assert lights.red_margin("a", 52.0, stations, 1.0) == REACH_M
    assert lights.red_margin("a", 55.0, stations, 7.0) == REACH_M
    # Approaching at red: the distance to the line; crossing it: negative, until PAST_M past it.
    assert lights.red_margin("b", 40.0, stations, 7.0) == 10.0
    assert lights.red_margin("b", 53.0, stations, 8.0) == -3.0
    assert lights.red_margin("b", 50.0 + PAST_M + 1.0, stations, 9.0) == REACH_M


def test_scalar_and_array_states_agree():
    p = Program(3.0, 1.0, 2.0, 0.5)
    t = np.linspace(0.0, 20.0, 401)
    changes = [(5.0, "red"), (9.0, "program")]
    assert list(state_at(p, changes, t)) == [state_at(p, changes, float(x)) for x in t]


@pytest.mark.parametrize("state", ["green", "yellow", "red"])
def test_a_change_holds_from_its_time(state):
    p = Program(1.0, 1.0, 1.0)
    assert state_at(p, [(2.0, state)], 2.0) == {"green": GREEN, "yellow": YELLOW, "red": RED}[state]
