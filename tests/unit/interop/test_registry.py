"""The importer's element registries (addt_dsl/interop/openscenario/registry.py): the translator
dispatches through them, an element in none is refused, every entry names an element of the
OpenSCENARIO 1.3 schema, and the coverage table of docs/openscenario.md is what they say."""

from __future__ import annotations

import importlib.util
import re

import pytest

from addt_dsl.interop.openscenario.coverage import coverage, status_of
from addt_dsl.interop.openscenario.importer import import_xosc
from addt_dsl.interop.openscenario.registry import (ACTIONS, ENTITY_CONDITIONS, GLOBAL_ACTIONS, INIT_ACTIONS,
                                                    INIT_GLOBAL_ACTIONS, POSITIONS, STATUSES, STORYBOARD,
                                                    VALUE_CONDITIONS, ElementRegistry)
from tests.conftest import ROOT

ESMINI = ROOT / "tests" / "data" / "esmini"
CUT_IN = ESMINI / "xosc" / "cut-in_simple.xosc"  # Init speeds and teleports, one lane change in an event
needs_schema = pytest.mark.skipif(importlib.util.find_spec("qc_openscenario") is None,
                                  reason="the OpenSCENARIO schema comes with asam-qc-openscenarioxml")


def test_a_registry_takes_each_element_once_with_a_known_status():
    registry = ElementRegistry("action")
    registry.declare("LaneOffsetAction", "refused", "no lateral offsets")
    with pytest.raises(ValueError, match="registered twice"):
        registry.declare("LaneOffsetAction", "refused", "again")
    with pytest.raises(ValueError, match="status"):
        registry.declare("TrailerAction", "maybe", "not a status")
    assert registry.translator("LaneOffsetAction") is None and registry.translator("Unknown") is None
    assert all(e.status in STATUSES and e.note for e in coverage())


def test_the_translator_dispatches_through_the_registry(monkeypatch):
    # The file imports with its lane change; without the registered translation of
    # LaneChangeAction, the same element is refused at its line (E0803), as an element in no
    # registry is.
    assert import_xosc(CUT_IN, root=ESMINI, ego="scripted").text is not None
    monkeypatch.delitem(ACTIONS._entries, "LaneChangeAction")
    got = import_xosc(CUT_IN, root=ESMINI, ego="scripted")
    refused = [d for d in got.diagnostics if d.code == "E0803"]
    assert got.text is None and len(refused) == 1 and refused[0].span.line == 92, got.diagnostics
    assert "<LaneChangeAction> is not translated" in refused[0].message


def test_an_init_action_dispatches_through_its_registry(monkeypatch):
    monkeypatch.delitem(INIT_ACTIONS._entries, "TeleportAction")
    got = import_xosc(CUT_IN, root=ESMINI, ego="scripted")
    refused = [d for d in got.diagnostics if d.code == "E0803"]
    assert got.text is None and refused and all("<TeleportAction> in Init is not translated" in d.message
                                                for d in refused), got.diagnostics


def _schema():
    from docs.osc_schema import table
    return table()


@needs_schema
def test_every_entry_names_an_element_of_the_schema():
    # A misspelt name would never be dispatched to, nor appear in the coverage table.
    entries = _schema()
    segments = {cat: {seg for e in entries if e.category == cat for seg in e.path.split("/")}
                for cat in ("action", "condition", "position")}
    paths = {e.path for e in entries if e.category == "storyboard"}
    for registry, names in ((ACTIONS, segments["action"]), (INIT_ACTIONS, segments["action"]),
                            (GLOBAL_ACTIONS, segments["action"]), (INIT_GLOBAL_ACTIONS, segments["action"]),
                            (VALUE_CONDITIONS, segments["condition"]), (ENTITY_CONDITIONS, segments["condition"]),
                            (POSITIONS, segments["position"]), (STORYBOARD, paths)):
        unknown = [e.name for e in registry.entries() if e.name not in names]
        assert not unknown, f"{registry.family}: {unknown} are not OpenSCENARIO 1.3 elements"


@needs_schema
def test_every_storyboard_element_and_translated_action_has_an_entry():
    for e in _schema():
        if e.category == "storyboard":
            assert status_of(e.category, e.path)[""] is not None, e.path
    assert status_of("action", "PrivateAction/LongitudinalAction/SpeedAction")["event"].translate is not None
    assert status_of("action", "GlobalAction/TrafficAction/TrafficSwarmAction")["event"].status == "refused"
    assert status_of("action", "GlobalAction/EnvironmentAction")["Init"].translate is not None


@needs_schema
def test_the_coverage_table_in_the_docs_is_the_registries():
    from docs.osc_coverage import markdown
    text = (ROOT / "docs" / "openscenario.md").read_text(encoding="utf-8")
    shown = re.search(r'<!-- regen="python -m docs.osc_coverage" -->\n(.*?)<!-- /regen -->', text, re.S)
    assert shown is not None, "docs/openscenario.md has no coverage table"
    assert shown.group(1) == markdown(), "the coverage table is out of date: run `python docs/regen.py " \
                                         "docs/openscenario.md`"
