"""Numbers the importer adds up from a file's decimals are the decimals' sum, not float
noise: a stop trigger at 3.6 s with a 0.2 s delay ends the run at 3.8 s (float addition:
3.8000000000000003, printed back as that), signal phases of 0.1 s and 0.2 s make a 0.3 s
cycle. Whatever is printed reads back to the same float."""

from fractions import Fraction

from hypothesis import given
from hypothesis import strategies as st

from addt_dsl import units
from addt_dsl.compiler import compile_file
from addt_dsl.interop.openscenario.importer import import_xosc
from tests.unit.interop.test_xosc_import import ESMINI, SMALL, _lights_file, _phase

STOP = """<StopTrigger><ConditionGroup><Condition name="end" delay="0.2" conditionEdge="rising"><ByValueCondition>
      <SimulationTimeCondition value="3.6" rule="greaterThan"/></ByValueCondition></Condition></ConditionGroup>
    </StopTrigger>"""
CAR = ('<Vehicle name="car" vehicleCategory="car"><BoundingBox><Center x="1.4" y="0" z="0.8"/>'
       '<Dimensions width="2" length="5" height="1.5"/></BoundingBox><Performance maxSpeed="70" '
       'maxAcceleration="10" maxDeceleration="10"/><Axles><FrontAxle maxSteering="0.5" wheelDiameter="0.8" '
       'trackWidth="1.68" positionX="2.98" positionZ="0.4"/><RearAxle maxSteering="0" wheelDiameter="0.8" '
       'trackWidth="1.68" positionX="0" positionZ="0.4"/></Axles><Properties/></Vehicle>')

CONTROLLER = '<ObjectController><Controller name="agent"><Properties/></Controller></ObjectController>'


def test_a_stop_time_plus_its_delay_is_their_decimal_sum(tmp_path):
    (tmp_path / "r.xodr").write_text((ESMINI / "xodr" / "straight_500m.xodr").read_text())
    (tmp_path / "s.xosc").write_text(SMALL.replace("ENTITY", CAR).replace("<StopTrigger/>", STOP))
    got = import_xosc(tmp_path / "s.xosc", lenient=True)
    assert got.text is not None, [d.message for d in got.diagnostics]
    assert got.plan.duration_s == 3.8
    assert "duration 3.8 s" in got.text and "3.8000000000000003" not in got.text
    (tmp_path / "s.addt").write_text(got.text)
    again = compile_file(tmp_path / "s.addt")
    assert again.ok, again.diagnostics
    assert again.plan.duration_s == got.plan.duration_s


def test_signal_phases_sum_to_their_decimal_cycle(tmp_path):
    phases = _phase("stop", 0.2, "on;off;off") + _phase("go", 0.1, "off;off;on") + _phase("go2", 0.2, "off;off;on") \
        + _phase("wait", 0.1, "off;on;off")
    got = _lights_file(tmp_path, phases)
    assert got.text is not None, [d.message for d in got.diagnostics]
    (ctl,) = got.plan.controllers
    # green 0.1 + 0.2 = 0.3 s (float addition: 0.30000000000000004), its run starting 0.2 s in.
    assert [e.value for e in (ctl.green_s, ctl.yellow_s, ctl.red_s, ctl.offset_s)] == [0.3, 0.1, 0.2, 0.2]
    assert "0.30000000000000004" not in got.text


DECIMALS = st.decimals(min_value=-1e6, max_value=1e6, places=4, allow_nan=False, allow_infinity=False)


@given(st.lists(DECIMALS, max_size=8))
def test_decimal_sum_is_the_sum_of_the_decimals_rounded_once(values):
    floats = [float(v) for v in values]
    exact = sum((Fraction(v) for v in values), Fraction(0))
    assert units.decimal_sum(floats) == float(exact)


def test_speed_profile_times_are_decimal_sums_of_the_entry_durations(tmp_path):
    # esmini's speed-profile.xosc with entry durations 0.1, 0.2, 0.3 s: points at 0.1, 0.3, 0.6 s
    # (float addition: 0.30000000000000004, 0.6000000000000001).
    import shutil

    (tmp_path / "xodr").mkdir()
    shutil.copy(ESMINI / "xodr" / "straight_500m.xodr", tmp_path / "xodr")
    shutil.copytree(ESMINI / "xosc" / "Catalogs", tmp_path / "xosc" / "Catalogs")
    text = (ESMINI / "xosc" / "speed-profile.xosc").read_text()
    for old, new in (('time="4.0" speed="10.0"', 'time="0.1" speed="10.0"'),
                     ('time="4.0" speed="4.0"', 'time="0.2" speed="4.0"'),
                     ('time="2.0" speed="8.0"', 'time="0.3" speed="8.0"')):
        assert old in text
        text = text.replace(old, new)
    (tmp_path / "xosc" / "sp.xosc").write_text(text)
    got = import_xosc(tmp_path / "xosc" / "sp.xosc", root=tmp_path, lenient=True, ego="scripted")
    assert got.text is not None, [d.message for d in got.diagnostics]
    profiles = [c for a in got.plan.actors() for c in [*a.behaviors, *(t.clause for t in a.triggers)]
                if c.name == "speed_profile"]
    assert profiles
    for clause in profiles:
        assert [v.value for v in clause.settings["times"]] == [0.0, 0.1, 0.3, 0.6]
    assert "0.30000000000000004" not in got.text and "0.6000000000000001" not in got.text


def test_a_speed_limit_in_km_h_is_imported_exactly(tmp_path):
    # A map's 50 km/h is 13.88888888888889 m/s: kept exactly (the printer writes `50 km/h`),
    # not rounded to 13.888889 m/s, a value no one wrote. (The standing ego has a controller
    # of its own, someone else's to drive: the stack drives it at the limit.)
    xodr = (ESMINI / "xodr" / "straight_500m.xodr").read_text()
    head = '<road name="" length="5.0000000000000000e+02" id="1" junction="-1">'
    assert head in xodr
    xodr = xodr.replace(head, head + '<type s="0" type="town"><speed max="50" unit="km/h"/></type>')
    (tmp_path / "r.xodr").write_text(xodr)
    (tmp_path / "s.xosc").write_text(SMALL.replace("ENTITY", CAR + CONTROLLER))
    got = import_xosc(tmp_path / "s.xosc", lenient=True)
    assert got.text is not None, [d.message for d in got.diagnostics]
    assert got.plan.ego.stack.settings["cruise_speed"].value == units.to_si(50, "km/h")[0]
    assert "cruise_speed 50 km/h" in got.text
