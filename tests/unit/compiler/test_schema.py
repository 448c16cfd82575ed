"""The committed plan schema is the one the code produces, and plans validate against it."""

from __future__ import annotations

import json

from tests.unit.compiler.conftest import CASES_DIR, REPO

from addt_dsl.cli import main
from addt_dsl.compiler import compile_file
from addt_dsl.plan import SCHEMA_VERSION, ScenarioPlan, plan_json_schema

SCHEMA_FILE = REPO / "docs" / "plan.schema.json"


def test_committed_schema_is_up_to_date():
    committed = json.loads(SCHEMA_FILE.read_text())
    assert committed == plan_json_schema(), \
        "docs/plan.schema.json is stale: run `addtc schema --write docs/plan.schema.json`"


def test_schema_command_writes_the_file(tmp_path, capsys):
    out = tmp_path / "schema.json"
    assert main(["schema", "--write", str(out)]) == 0
    assert json.loads(out.read_text()) == plan_json_schema()


def test_schema_is_versioned():
    schema = plan_json_schema()
    assert schema["$id"].endswith(f"plan-v{SCHEMA_VERSION}.json")
    assert schema["properties"]["schema_version"]["const"] == SCHEMA_VERSION


def test_a_full_plan_round_trips_through_json():
    plan = compile_file(CASES_DIR / "ok_full.addt").plan
    assert plan is not None
    again = ScenarioPlan.model_validate_json(plan.model_dump_json())
    assert again == plan
    assert any(a.triggers for a in plan.agents)


def test_plans_validate_against_the_committed_schema():
    import jsonschema  # a test dependency (the `test` extra): never skipped

    schema = json.loads(SCHEMA_FILE.read_text())
    for path in (CASES_DIR / "ok_full.addt", REPO / "examples" / "overtake.addt"):
        plan = compile_file(path).plan
        jsonschema.validate(json.loads(plan.model_dump_json()), schema)
