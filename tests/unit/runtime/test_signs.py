"""Stop signs (runtime/signs.py): which signals are stop signs, their lines, the margin."""

from addt_dsl.road.road import Signal
from addt_dsl.runtime.lights import PAST_M, REACH_M, StopStation
from addt_dsl.runtime.signs import SIGN, SignsRuntime, is_stop_sign, next_sign


def test_stop_sign_types():
    assert is_stop_sign(Signal("1", 10.0, -3.0, type="206"))
    assert is_stop_sign(Signal("2", 10.0, -3.0, type=" R1-1 "))
    assert not is_stop_sign(Signal("3", 10.0, -3.0, type="205"))  # a yield sign
    assert not is_stop_sign(Signal("4", 10.0, -3.0, type="206", dynamic=True))
    assert not is_stop_sign(Signal("5", 10.0, -3.0, type="1000001", dynamic=True))


def test_next_sign_skips_lines_behind_and_those_stopped_for():
    lines = [50.0, 80.0, 300.0]
    assert next_sign(lines, 10.0) == 50.0
    assert next_sign(lines, 50.4) == 50.0  # a front just over the line still meets it
    assert next_sign(lines, 51.0) == 80.0
    assert next_sign(lines, 10.0, stopped=(50.0,)) == 80.0
    assert next_sign(lines, 81.0) is None  # 300 m is beyond the 100 m reach
    assert next_sign(lines, 81.0 + 300.0 - 80.0 - REACH_M) == 300.0


def test_margin_until_stopped_then_the_next_line():
    signs, st = SignsRuntime(), [StopStation(50.0, SIGN), StopStation(90.0, SIGN)]
    assert signs.margin("a", 10.0, 8.0, st) == 40.0
    assert signs.margin("a", 45.0, 0.5, st) == 5.0  # slow but not stopped, 5 m short
    assert signs.margin("a", 47.0, 0.05, st) == 43.0  # stopped 3 m short: the next line counts
    assert signs.margin("a", 55.0, 6.0, st) == 35.0  # over the first line: it had stopped
    assert signs.margin("a", 92.0, 6.0, st) == -2.0  # over the second without stopping
    assert signs.margin("a", 90.0 + PAST_M - 1.0, 6.0, st) == -(PAST_M - 1.0)
    assert signs.margin("a", 90.0 + PAST_M + 1.0, 6.0, st) == REACH_M


def test_a_stop_too_far_back_does_not_count_and_actors_are_apart():
    signs, st = SignsRuntime(), [StopStation(50.0, SIGN)]
    assert signs.margin("a", 40.0, 0.0, st) == 10.0  # stood 10 m back (a queue): not for the line
    assert signs.margin("a", 51.0, 3.0, st) == -1.0
    assert signs.margin("b", 47.0, 0.0, st) == REACH_M  # b stopped for it; a's state is a's
    assert signs.margin("b", 51.0, 3.0, st) == REACH_M


def test_an_actor_that_starts_past_a_line_never_ran_it():
    signs, st = SignsRuntime(), [StopStation(50.0, SIGN)]
    assert signs.margin("a", 52.0, 10.0, st) == REACH_M


def test_lines_of_a_maps_stop_signs_by_the_way_they_face():
    from pathlib import Path

    from addt_dsl.road.xodr import parse_xodr
    from addt_dsl.runtime.signs import stop_sign_lines

    text = (Path(__file__).resolve().parents[2] / "data" / "xodr" / "straight_500m.xodr").read_text()
    signals = """<signals>
            <signal s="150.0" t="-4.0" id="900" dynamic="no" orientation="+" type="206"/>
            <signal s="300.0" t="4.0" id="901" dynamic="no" orientation="-" type="206"/>
            <signal s="200.0" t="-4.0" id="902" dynamic="no" orientation="+" type="205"/>
            <signal s="250.0" t="-4.0" id="903" dynamic="no" orientation="none" type="R1-1">
                <validity fromLane="-1" toLane="-1"/>
            </signal>
        </signals>"""
    network = parse_xodr(text.replace("<signals>\n        </signals>", signals))
    got = [(ln.signal, ln.s, ln.direction, ln.lanes) for ln in stop_sign_lines(network)]
    # Lane -1 drives along +s, lane 1 against (right-hand traffic); the yield sign is none.
    assert got == [("900", 150.0, 1, (-1,)), ("901", 300.0, -1, (1,)), ("903", 250.0, 1, (-1,))]
