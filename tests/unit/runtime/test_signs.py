"""Signs (runtime/signs.py): which signals are stop, yield and priority signs, their lines
(signal references included), the stop-sign margin, the junction rule."""

import math
from pathlib import Path

import pytest

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


TOWN07 = Path(__file__).resolve().parents[2] / "data" / "carla" / "town07_signal_refs.xodr"


def test_signal_references_place_town07s_signs_on_the_connecting_roads():
    """Town07's stop sign 983 stands on road 1 with validity 0..0 (no lane: it held no one);
    its `<signalReference>`s on connecting roads 151 (s 0.4857) and 153 (s 3.0462) name lane
    -1 (along +s): a line on each. The yield sign 995 (road 3) is referenced by road 295 at
    s 14.3507 for lane 1 (against s). The references' orientation ("-" for lane -1, "+" for
    lane 1) is the way the sign's face points, opposite to the standard's: the validity decides."""
    from addt_dsl.road.xodr import load_xodr
    from addt_dsl.runtime.signs import sign_lines, stop_sign_lines

    network = load_xodr(TOWN07)
    got = [(ln.controller, ln.signal, ln.road_id, round(ln.s, 4), ln.direction, ln.lanes)
           for ln in sign_lines(network)]
    assert got == [("stop", "983", "151", 0.4857, 1, (-1,)), ("stop", "983", "153", 3.0462, 1, (-1,)),
                   ("yield", "995", "295", 14.3507, -1, (1,))]
    assert [ln.road_id for ln in stop_sign_lines(network)] == ["151", "153"]
    # Where the line on road 151 meets its lane, by hand from the file: its first geometry
    # is a line from (-192.20995, -50.01225) at hdg 3.1329194 rad; at s = 0.4856626:
    # x = -192.20995 + 0.4856626 cos(hdg) = -192.69560, y = -50.01225 + 0.4856626 sin(hdg)
    # = -50.00804; lane -1 (3.1 m wide) is centred at t = -1.55: (x + 1.55 sin hdg,
    # y - 1.55 cos hdg) = (-192.68216, -48.45809).
    road = network.road("151")
    x, y, hdg = road.reference_pose(0.4856626104422759)
    t = road.lane_center_t(-1, 0.4856626104422759)
    assert t == pytest.approx(-1.55)
    assert (x - t * math.sin(hdg), y + t * math.cos(hdg)) == pytest.approx((-192.68216, -48.45809), abs=1e-5)


def test_a_reference_places_a_traffic_light_too():
    """Light 980 (road 115, validity 0..0) holds lane 1 of connecting road 71 at s 11.4324."""
    from addt_dsl.road.xodr import load_xodr
    from addt_dsl.runtime.lights import StopLine, stop_lines

    network = load_xodr(TOWN07)
    assert stop_lines(network, "c", ["980"]) == [StopLine("c", "980", "71", 11.43236314212659, -1, (1,))]
    # Without the references, as before: no line (the signal's own validity is lane 0).
    bare = TOWN07.read_text().replace("<signalReference ", "<ignoredReference ").replace(
        "</signalReference>", "</ignoredReference>")
    from addt_dsl.road.xodr import parse_xodr
    assert stop_lines(parse_xodr(bare), "c", ["980"]) == []


def test_sign_kinds_by_type_from_the_registry():
    from addt_dsl.runtime.signs import SIGN_KINDS, sign_kind

    from addt_dsl.runtime.signs import RULES

    types = ("206", "R1-1", "205", " R1-2", "301", "306", "307")
    assert [sign_kind(Signal("1", 1.0, 0.0, type=t)) for t in types] == \
        ["stop", "stop", "yield", "yield", "priority", "priority_road", "priority_road_end"]
    assert sign_kind(Signal("1", 1.0, 0.0, type="274")) is None  # a speed limit
    assert sign_kind(Signal("1", 1.0, 0.0, type="205", dynamic=True)) is None
    assert list(SIGN_KINDS) == ["stop", "yield", "priority", "priority_road", "priority_road_end"]
    # What each gives its approach and the priority road (StVO: 306 begins one; 307, a yield
    # or a stop sign ends it; 301 leaves it as it is).
    assert [(k.rule, k.road) for k in SIGN_KINDS.values()] == \
        [("stop", False), ("yield", False), ("priority", None), ("priority", True), (None, False)]
    assert {k.rule for k in SIGN_KINDS.values()} - {None} == set(RULES)


def test_the_junction_rule_is_the_signs_between_the_previous_junction_and_this_ones_exit():
    from addt_dsl.runtime.signs import junction_rule

    junctions = [(100.0, 120.0, 0.0, 0.0), (300.0, 320.0, 0.0, 0.0)]
    st = [StopStation(95.0, "priority"), StopStation(101.0, "yield"), StopStation(250.0, "priority")]
    # Before and in the first junction: the yield (inside it, as a reference places it) wins.
    assert junction_rule(st, junctions, 50.0) == "yield"
    assert junction_rule(st, junctions, 119.0) == "yield"
    assert junction_rule(st, junctions, 121.0) == "priority"  # the second's: its sign at 250 m
    assert junction_rule(st, junctions, 321.0) is None  # past the last junction
    assert junction_rule(st[2:], [(400.0, 420.0)], 0.0) is None  # 150 m before the entry: beyond REACH_M
    assert junction_rule([], junctions, 50.0) is None


# Three junctions 200 m apart on the ego's path: (entry, exit) stations [m].
THREE = [(100.0, 120.0, 0.0, 0.0), (300.0, 320.0, 0.0, 0.0), (500.0, 520.0, 0.0, 0.0)]
FRONTS = (50.0, 200.0, 400.0, 600.0)  # before each junction, then past the last


def _rules(*signs: tuple[float, str]) -> list:
    """The rule of each junction of `THREE` (and past them) for signs (station [m], OpenDRIVE
    type) on the path, their kinds read from the registry as the runtime reads them."""
    from addt_dsl.runtime.signs import junction_rule, sign_kind

    stations = [StopStation(u, sign_kind(Signal("1", 1.0, 0.0, type=t))) for u, t in signs]
    return [junction_rule(stations, THREE, front) for front in FRONTS]


def test_a_priority_road_keeps_priority_at_every_junction_a_301_only_at_the_next():
    # StVO 306: priority at every junction along the road until it ends; 301: at the next one.
    assert _rules((90.0, "306")) == ["priority", "priority", "priority", None]
    assert _rules((90.0, "301")) == ["priority", None, None, None]
    # A 306 further than 100 m before the junction still begins the road (the approach's own
    # rule reaches 100 m only, as a 301 so placed shows).
    assert _rules((20.0, "306")) == ["priority", "priority", "priority", None]
    assert _rules((250.0, "306")) == [None, "priority", "priority", None]
    assert _rules((150.0, "301")) == [None, None, None, None]


def test_sign_307_ends_the_priority_road():
    assert _rules((90.0, "306"), (250.0, "307")) == ["priority", None, None, None]
    # Begun again after it: priority from there on.
    assert _rules((90.0, "306"), (250.0, "307"), (450.0, "306")) == ["priority", None, "priority", None]
    # On one station, 307 after 306 (the registry's order): the 306 gives its own approach
    # priority, the road ends there.
    assert _rules((90.0, "306"), (90.0, "307")) == ["priority", None, None, None]
    assert _rules((90.0, "306")) == ["priority"] * 3 + [None]  # without the 307


def test_an_approach_with_a_yield_or_stop_sign_ends_the_priority_road():
    # The junction's own sign outranks the road's priority, and the road ends with it.
    assert _rules((90.0, "306"), (295.0, "205")) == ["priority", "yield", None, None]
    assert _rules((90.0, "306"), (295.0, "R1-1")) == ["priority", "stop", None, None]
    # A 301 after it gives the next junction priority again, only that one.
    assert _rules((90.0, "306"), (295.0, "205"), (495.0, "301")) == ["priority", "yield", "priority", None]
    # On the road, a junction's stop sign beside a 306 (stop > priority) still ends it.
    assert _rules((90.0, "306"), (295.0, "306"), (296.0, "206")) == ["priority", "stop", None, None]
    assert _rules((90.0, "306")) == ["priority"] * 3 + [None]  # without the yield sign
