"""docs/osc_schema.py lists the OpenSCENARIO 1.3 schema's actions, conditions, positions,
distributions and storyboard elements, with 1.2's as a subset (checked against the
standards' XSDs as shipped with the ASAM checker, by names known from their texts)."""

from __future__ import annotations

import importlib.util
import json
import sys

import pytest

from tests.conftest import ROOT

spec = importlib.util.spec_from_file_location("osc_schema", ROOT / "docs" / "osc_schema.py")
osc_schema = importlib.util.module_from_spec(spec)
sys.modules["osc_schema"] = osc_schema  # its dataclass looks its module up
spec.loader.exec_module(osc_schema)


@pytest.fixture(scope="module")
def entries():
    if importlib.util.find_spec("qc_openscenario") is None:
        pytest.skip("asam-qc-openscenarioxml is not installed")
    return {(e.category, e.path): e for e in osc_schema.table()}


def test_every_category_and_the_new_elements_of_1_3(entries):
    by_name = {(c, p.rsplit("/", 1)[-1]): e for (c, p), e in entries.items()}
    counts = {c: sum(1 for k in entries if k[0] == c) for c in ("action", "condition", "position", "distribution",
                                                                "storyboard")}
    assert counts["position"] == 10 and counts["condition"] == 24 and counts["action"] >= 35, counts
    # New in 1.3 (ASAM OpenSCENARIO XML 1.3 release notes): not in 1.2.
    for category, name in (("condition", "AngleCondition"), ("condition", "RelativeAngleCondition"),
                           ("action", "RandomRouteAction"), ("action", "SetMonitorAction"),
                           ("action", "TrafficAreaAction"), ("action", "ConnectTrailerAction"),
                           ("distribution", "LogNormalDistribution")):
        assert not by_name[(category, name)].in_1_2, name
    for category, name in (("action", "SpeedAction"), ("action", "LightStateAction"), ("action", "TrafficSwarmAction"),
                           ("condition", "VariableCondition"), ("distribution", "PoissonDistribution"),
                           ("distribution", "ValueSetDistribution"), ("position", "TrajectoryPosition")):
        assert by_name[(category, name)].in_1_2, name
    assert entries[("action", "GlobalAction/VariableAction/SetAction")].in_1_2
    assert entries[("condition", "ByEntityCondition/EntityCondition/ReachPositionCondition")].deprecated


def test_the_script_prints_markdown_and_json(entries, capsys):
    assert osc_schema.main(["--format", "json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert len(rows) == len(entries) and {"category", "path", "in_1_2", "deprecated", "name"} <= set(rows[0])
    assert osc_schema.main([]) == 0
    assert "| action | `PrivateAction/LongitudinalAction/SpeedAction` | yes |" in capsys.readouterr().out
