"""Acts started by another act's completion, EndOfRoadCondition, events run several times
(esmini's lane_change_simple.xosc): what the importer writes, and what it still refuses."""

from __future__ import annotations

import shutil

from addt_dsl.interop.openscenario.importer import import_xosc
from tests.conftest import ROOT

ESMINI = ROOT / "tests" / "data" / "esmini"
FILE = ESMINI / "xosc" / "lane_change_simple.xosc"


def variant(tmp_path, old: str, new: str):
    """lane_change_simple with one edit, beside copies of its road and catalogs."""
    text = FILE.read_text()
    assert text.count(old) >= 1, old
    shutil.copytree(ESMINI / "xodr", tmp_path / "xodr")
    shutil.copytree(ESMINI / "xosc" / "Catalogs", tmp_path / "xosc" / "Catalogs")
    (tmp_path / "xosc" / "v.xosc").write_text(text.replace(old, new, 1))
    return import_xosc(tmp_path / "xosc" / "v.xosc", root=tmp_path, ego="scripted")


def test_lane_change_simple_translates_its_acts_road_ends_and_repeats():
    got = import_xosc(FILE, root=ESMINI, ego="scripted")
    assert got.plan is not None, [d.message for d in got.diagnostics if d.is_error]
    text = got.text
    # EndOfRoadCondition duration="2.5", rising: an edge of the held condition.
    assert "End_Of_Road_teleport_event: when rising road_end(ego) <= 0 m for 2.5 s repeat 3 then behavior " \
           "teleport s 10 m t -1.535 m" in text
    assert "when rising road_end(ego) <= 0 m repeat 2 then behavior teleport" in text  # duration 0
    # The second act: a group started when every event of the first has run its count, 4 s later.
    assert ("Lane_change_act_2: when rising ended(ego.Lane_change_event) and ended(ego.End_Of_Road_teleport_event)"
            " and ended(ego.End_Of_Road_speed_event) delayed 4 s then parallel {") in text
    # Its event without a start trigger: true once its act has started, twice.
    assert "Act_2_init_event: when started(ego.Lane_change_act_2) repeat 2 then behavior cruise" in text
    assert ("end when rising ended(ego.Act_2_init_event) and ended(ego.Act_2_Lane_change_event) and "
            "ended(ego.Act_2_End_Of_Road_teleport_event) delayed 8 s") in text
    # The speed changes over a time, from the speed it has then, within the catalog's Performance.
    assert text.count("cruise speed 25 m/s shape cubic duration 4 s max_accel 5 m/s^2 max_decel 10 m/s^2") == 3
    assert got.plan.duration_s == 300.0  # (bounded: the stop condition ends it)


def test_an_end_of_road_duration_beside_another_condition_is_refused(tmp_path):
    got = variant(tmp_path, """<EndOfRoadCondition duration="2.5"/>
                                    </EntityCondition>
                                </ByEntityCondition>
                           </Condition>""", """<EndOfRoadCondition duration="2.5"/>
                                    </EntityCondition>
                                </ByEntityCondition>
                           </Condition>
                           <Condition name="late" delay="0" conditionEdge="none">
                              <ByValueCondition><SimulationTimeCondition value="1" rule="lessThan"/></ByValueCondition>
                           </Condition>""")
    assert got.plan is None
    assert any(d.code == "E0803" and "end-of-road duration" in d.message for d in got.diagnostics)


def test_an_act_started_by_another_act_starting_stays_refused(tmp_path):
    got = variant(tmp_path, 'storyboardElementRef="Lane change act"\n' + " " * 57 + 'state="completeState"',
                  'storyboardElementRef="Lane change act" state="startTransition"')
    assert got.plan is None
    assert any(d.code == "E0803" and "act start conditions other than" in d.message for d in got.diagnostics)


def test_an_event_without_a_trigger_run_twice_in_an_act_from_the_start_stays_refused(tmp_path):
    text = FILE.read_text()
    start = text.index('<Event name="Lane change event"')
    trigger = text.index("<StartTrigger>", start)
    got = variant(tmp_path, text[trigger:text.index("</StartTrigger>", trigger) + len("</StartTrigger>")],
                  "<StartTrigger/>")
    assert got.plan is None
    assert any(d.code == "E0803" and "without a start condition of its own" in d.message for d in got.diagnostics)
