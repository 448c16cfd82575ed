"""`--stack KEY=VALUE`: a setting of the ego's stack given on the command line compiles as if
the file said it (addt_dsl/compiler/overrides.py), with diagnostics pointing into the text."""

import pytest

from addt_dsl.cli import main
from addt_dsl.compiler import compile_file, compile_source
from addt_dsl.compiler.overrides import parse_override
from addt_dsl.sweep import expand
from tests.conftest import EXAMPLES, HAS_TORCH

needs_torch = pytest.mark.skipif(not HAS_TORCH, reason="needs torch (the `learned` extra, see README)")

LIDAR5 = "sensor lidar rate 10 Hz rays 360 channels 5 vfov 12 deg range 80 m"


def src(stack: str, faults: str = "") -> str:
    return (f"scenario s {{\n  duration 5 s\n  road r {{ line length 300 m }}\n"
            f"  param gap = 30 m in [20 m, 40 m]\n"
            f"  ego car on r lane -1 at 10 m speed 10 m/s {{\n    {stack}\n    {LIDAR5}\n  }}\n"
            f"  agent lead car on r lane -1 at 10 m + gap speed 8 m/s\n"
            + (f"  faults {{\n    {faults}\n  }}\n" if faults else "")
            + "  sweep {\n    grid gap in [20, 40] m\n    repeat 2\n  }\n}\n")


@needs_torch  # the file's own setting (learned) must compile
def test_an_override_gives_the_runs_of_the_file_that_says_it():
    said = expand(compile_source(src("stack bev perception ground_truth cruise_speed 12 m/s")).plan).specs
    learned = compile_source(src("stack bev perception learned cruise_speed 12 m/s"),
                             stack=["perception=ground_truth"])
    assert learned.ok and not learned.diagnostics
    assert [s.key() for s in expand(learned.plan).specs] == [s.key() for s in said]
    # The setting stays where the file has it (a printed counterexample reads the same).
    assert list(learned.plan.ego.stack.settings) == ["perception", "cruise_speed"]


@needs_torch
def test_a_setting_the_file_lacks_is_added_and_a_missing_stack_clause_made():
    added = compile_source(src("stack bev"), stack=["time_gap=2 s", "aeb=off"]).plan.ego.stack
    assert added.settings["aeb"] == "off" and added.settings["time_gap"].value == pytest.approx(2.0)
    bare = compile_source(src("set mass 1600 kg"), stack=["perception=learned"])
    assert bare.ok and (bare.plan.ego.stack.name, bare.plan.ego.stack.settings) == ("bev", {"perception": "learned"})


@needs_torch
def test_what_depends_on_the_setting_follows_it():
    # A tensor fault site exists with the learned detector only.
    fault = "at 2 s bitflip perception.backbone.conv0 tensor weights"
    assert compile_source(src("stack bev perception learned", fault)).ok
    gt = compile_source(src("stack bev perception learned", fault), stack=["perception=ground_truth"])
    assert not gt.ok
    assert [(d.code, "perception.backbone.conv0" in d.message) for d in gt.diagnostics] == [("E0107", True)]


@pytest.mark.parametrize(("arg", "code", "col"), [
    ("perception=grund_truth", "E0204", 12),   # not a choice: the value is underlined
    ("percepton=ground_truth", "E0104", 1),    # not a setting: the key is
    ("cruise_speed=12 s", "E0201", 14),        # the wrong dimension
    ("perception=ground truth", "E0001", 19),  # not one expression
])
def test_a_wrong_override_is_a_diagnostic_in_the_command_line_text(arg, code, col):
    result = compile_source(src("stack bev"), stack=[arg])
    (d,) = [d for d in result.diagnostics if d.severity.name.lower() == "error"]
    assert (d.code, d.span.file, d.span.col) == (code, "--stack", col)
    assert result.sources["--stack"] == arg


def test_malformed_overrides_are_usage_errors(capsys):
    for text in ("perception", "=learned", "perception=", "2x=1"):
        with pytest.raises(ValueError):
            parse_override(text)
    with pytest.raises(SystemExit):
        main(["check", str(EXAMPLES / "suites" / "state_flip_overtake_copy.addt"), "--stack", "perception"])
    assert "expected KEY=VALUE" in capsys.readouterr().err


def test_the_paper_suites_screening_variant_from_the_cli(capsys):
    path = EXAMPLES / "suites" / "state_flip_overtake_copy.addt"
    if HAS_TORCH:  # the screening variant itself needs no torch: the core install runs it
        assert compile_file(path).plan.ego.stack.settings["perception"] == "learned"
    assert compile_file(path, stack=["perception=ground_truth"]).plan.ego.stack.settings["perception"] \
        == "ground_truth"
    assert main(["plan", str(path), "--stack", "perception=ground_truth"]) == 0
    assert '"perception": "ground_truth"' in capsys.readouterr().out


def test_the_studies_take_the_option_too(capsys):
    path = str(EXAMPLES / "suites" / "state_flip_overtake_copy.addt")
    with pytest.raises(SystemExit):
        main(["study", "classify", path, "--stack", "perception"])
    assert "expected KEY=VALUE" in capsys.readouterr().err
    assert main(["study", "classify", path, "--stack", "perception=grund_truth"]) == 2  # compiled, refused
    assert "--stack:1:12" in capsys.readouterr().err


def test_an_override_gives_a_scripted_ego_an_open_loop_stack():
    """A scripted ego without a stack has none (and no sensors); `--stack` makes the clause,
    with the default lidar, as if the file said `stack bev ...`."""
    text = ("scenario s {\n  duration 5 s\n  road r { line length 300 m }\n"
            "  ego car on r lane -1 at 10 m speed 10 m/s {\n    behavior cruise speed 12 m/s\n  }\n}\n")
    bare = compile_source(text).plan.ego
    assert bare.stack is None and bare.sensors == [] and bare.scripted
    given = compile_source(text, stack=["cruise_speed=20 m/s"])
    assert given.ok, given.diagnostics
    ego = given.plan.ego
    assert ego.stack.name == "bev" and ego.stack.settings["cruise_speed"].value == pytest.approx(20.0)
    assert [s.name for s in ego.sensors] == ["lidar"] and ego.scripted
