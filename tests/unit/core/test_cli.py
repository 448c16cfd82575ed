import json

from addt_dsl.cli import main
from tests.conftest import EXAMPLES


def test_check_ok(capsys):
    assert main(["check", str(EXAMPLES / "overtake.addt")]) == 0


def test_compile_error_exit_2_without_traceback(tmp_path, capsys):
    bad = tmp_path / "bad.addt"
    bad.write_text("scenario s {\n  duration 10 m\n}\n")
    assert main([str(bad)]) == 2
    err = capsys.readouterr().err
    assert "bad.addt:2:" in err and "Traceback" not in err


def test_binary_input_exit_2(tmp_path, capsys):
    bad = tmp_path / "bin.addt"
    bad.write_bytes(b"\x00\xff\xfe\x00garbage")
    assert main(["check", str(bad)]) == 2


def test_plan_prints_json(capsys):
    assert main(["plan", str(EXAMPLES / "overtake.addt")]) == 0
    plan = json.loads(capsys.readouterr().out)
    assert plan["schema_version"] == "1" and plan["name"] == "overtake"


def test_schema(capsys):
    assert main(["schema"]) == 0
    schema = json.loads(capsys.readouterr().out)
    assert schema["title"] == "addt-dsl ScenarioPlan"
