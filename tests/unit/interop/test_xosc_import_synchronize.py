"""`addtc import` of esmini's synchronisation scenarios: maneuver catalogs with their
parameter assignments, SynchronizeAction's tolerances and final speeds, StandStillCondition,
a target point beyond its road, and speed changes at a rate (esmini's reading)."""

from __future__ import annotations

import shutil

import pytest

from addt_dsl.interop.openscenario.importer import import_xosc
from addt_dsl.plan import ClausePlan
from tests.conftest import ROOT

ESMINI = ROOT / "tests" / "data" / "esmini"


def _clauses(agent) -> list[ClausePlan]:
    out = list(agent.behaviors)
    for t in agent.triggers:
        out += [t.clause] if t.clause is not None else [s.clause for s in t.group.steps]
    return out


def _sync(agent) -> ClausePlan:
    return next(c for c in _clauses(agent) if c.name == "synchronize")


def test_maneuver_catalog_uses_take_their_own_parameter_assignments():
    got = import_xosc(ESMINI / "xosc" / "synchronize.xosc", root=ESMINI)
    assert got.plan is not None, [d.message for d in got.diagnostics if d.is_error]
    agents = {a.name: a for a in got.plan.agents}
    # $MS1NPC as each maneuver group assigns it; `$MS1EgoS` assigned `$MS1EgoS` (the
    # global, read where the reference stands) is 300 m.
    for name, target in (("NPC1", 305.0), ("NPC2", 285.0), ("NPC3", 297.0), ("NPC4", 330.0)):
        sync = _sync(agents[name])
        assert sync.settings["target_s"].value == target
        assert sync.settings["master_at"].value == 300.0
        assert sync.settings["tolerance"].value == 1.0 and sync.settings["master_tolerance"].value == 1.0
        # RelativeSpeedToMaster delta 0: the master's speed, read while it runs.
        assert got.text.count("final_speed speed(ego) + 0 m/s") == 4
    # $NPCFreeSpeed of each use, the sinusoidal change at esmini's rate (its peak: 3 m/s^2),
    # also for NPC2 and NPC4, which the importer expects at rest when it starts.
    free = {name: next(c for c in _clauses(agents[name]) if c.name == "cruise" and "shape" in c.settings
                       and c.settings["shape"] == "sinusoidal") for name in ("NPC1", "NPC2", "NPC3", "NPC4")}
    assert {n: c.settings["speed"].value for n, c in free.items()} == {"NPC1": 30.0, "NPC2": 0.0, "NPC3": 17.0,
                                                                       "NPC4": 0.0}
    assert all(c.settings["accel"].value == 3.0 for c in free.values())


def test_an_event_after_the_end_of_a_synchronisation_starts_when_it_ends():
    # Keep_Relative_Speed starts on Synchronize_NPC_Event's completeState; a synchronisation
    # has no length in its settings, so not at 0 s but on its step's end (every use names
    # the first one, as esmini resolves a name used twice).
    got = import_xosc(ESMINI / "xosc" / "synchronize.xosc", root=ESMINI)
    for name in ("NPC1", "NPC2", "NPC3", "NPC4"):
        agent = next(a for a in got.plan.agents if a.name == name)
        keep = next(t for t in agent.triggers if t.clause is not None and t.clause.name == "cruise"
                    and t.clause.settings.get("shape") == "step")
        assert keep.at_s is None and keep.condition.left.name == "ended(NPC1.Synchronize_NPC_Event)"


@pytest.mark.parametrize("alone", [False, True])
def test_stand_still_condition_is_a_hold(alone, tmp_path):
    shutil.copytree(ESMINI, tmp_path / "e")
    path = tmp_path / "e" / "xosc" / "synchronize.xosc"
    if alone:  # without the travelled distance beside it: exactly esmini's condition
        text = path.read_text()
        start = text.index('<Condition name="EndCondition1"')
        path.write_text(text[:start] + text[text.index("</Condition>", start) + len("</Condition>"):])
    got = import_xosc(path, root=tmp_path / "e")
    assert got.plan is not None, [d.message for d in got.diagnostics if d.is_error]
    end = got.plan.end
    assert end.hold_s.value == 2.0
    cond = end.condition if alone else end.condition.right
    assert (cond.op, cond.left.name, cond.right.value) == ("<", "speed(NPC4)", 1e-3)
    warned = [d for d in got.diagnostics if "standstill" in d.message]
    assert [d.code for d in warned] == ([] if alone else ["W0802"])


def test_a_target_point_beyond_its_road_is_at_the_road_end_as_in_esmini():
    # LanePosition s = 455 m on road 2 (304.194 m long): esmini clamps s to the road.
    got = import_xosc(ESMINI / "xosc" / "ltap-od-relative-speed.xosc", root=ESMINI)
    assert got.plan is not None, [d.message for d in got.diagnostics if d.is_error]
    sync = _sync(next(a for a in got.plan.agents if a.name == "NPC"))
    assert sync.settings["target_s"].left.value == pytest.approx(304.194316553)
    assert any(d.code == "W0802" and "the road's end" in d.message for d in got.diagnostics)
    assert "final_speed speed(ego) - 3 m/s" in got.text
    # No tolerances given: esmini's default, 0 m.
    assert "tolerance" not in sync.settings and "master_tolerance" not in sync.settings


def test_synchronize_tolerances_and_absolute_final_speed():
    got = import_xosc(ESMINI / "xosc" / "ltap-od.xosc", root=ESMINI)
    sync = _sync(next(a for a in got.plan.agents if a.name == "NPC"))
    assert sync.settings["tolerance"].value == 1.0 and sync.settings["master_tolerance"].value == 1.0
    assert sync.settings["final_speed"].value == 7.0


def test_export_writes_tolerances_relative_final_speeds_and_peak_rates(tmp_path):
    import defusedxml.ElementTree as DET

    from addt_dsl.interop.xosc_export import export_run
    from addt_dsl.sweep import expand

    got = import_xosc(ESMINI / "xosc" / "synchronize.xosc", root=ESMINI)
    done = export_run(expand(got.plan).specs[0], tmp_path)
    root = DET.parse(done.xosc_path).getroot()
    syncs = root.findall(".//SynchronizeAction")
    assert len(syncs) == 4
    for action in syncs:
        assert (action.get("targetTolerance"), action.get("targetToleranceMaster")) == ("1.0", "1.0")
        rel = action.find("FinalSpeed/RelativeSpeedToMaster")
        assert (float(rel.get("value")), rel.get("speedTargetValueType")) == (0.0, "delta")
    rates = {float(d.get("value")) for d in root.findall(".//SpeedActionDynamics")
             if d.get("dynamicsShape") == "sinusoidal"}
    assert rates == {3.0}  # esmini's rate: the peak rate of change, as imported
    # And back: the same settings.
    again = import_xosc(done.xosc_path)
    assert again.plan is not None, [d.message for d in again.diagnostics if d.is_error]
    for name in ("NPC1", "NPC4"):
        before = _sync(next(a for a in got.plan.agents if a.name == name)).settings
        after = _sync(next(a for a in again.plan.agents if a.name == name)).settings
        for key in ("tolerance", "master_tolerance", "final_speed"):
            assert after[key] == before[key], key
