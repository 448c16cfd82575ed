"""Every example in docs/*.md and README.md compiles or runs as its block says
(tests/docs_harness.py says how blocks are read; tests/sim/test_docs_run.py runs the scenarios)."""

from __future__ import annotations

import importlib.util
from types import SimpleNamespace

import pytest

from addt_dsl.cli import SUBCOMMANDS, build_parser
from addt_dsl.compiler import compile_source
from addt_dsl.diagnostics import CODES
from tests.conftest import ROOT, assert_scenarios_compile
from tests.docs_harness import (
    CODES_WITHOUT_MODULE,
    FAULT_LINES,
    addtc_commands,
    blocks,
    expected_diagnostics,
    fault_scenario,
    ids,
    kind,
    kind_of,
    scenario_dir,
    section_code,
    source,
    verdicts,
)

ADDT = blocks("addt")
PYTHON = [b for b in blocks("python") if "fragment" not in b.attrs]


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    return scenario_dir(tmp_path_factory.mktemp("scenarios"))


def _found(result) -> set[tuple[str, int, int]]:
    return {(d.code, d.span.line if d.span else 0, d.span.col if d.span else 0) for d in result.diagnostics}


def test_the_docs_have_examples_of_every_kind():
    kinds = [kind(b) for b in ADDT]
    assert kinds.count("scenario") >= 20 and "file" in kinds and "snippet" in kinds
    assert "fragment" not in kinds, "an .addt example compiles, as a scenario or inside a wrapper"
    assert len(FAULT_LINES) >= 13 and len(PYTHON) >= 7


def test_verdicts_read_as_the_docs_state_them():
    def run(passed, failed=(), warned=()):
        records = [SimpleNamespace(name=n, severity="warn", passed=False) for n in warned]
        return SimpleNamespace(passed=passed, failed_oracles=list(failed), verdicts=records)

    runs = [run(True, warned=["max_jerk"]), run(False, ["no_collision", "min_ttc"]), run(False, ["min_ttc"])]
    assert str(verdicts(runs)) == "1 passed, 2 failed (min_ttc 2, no_collision 1), warned (max_jerk 1)"
    assert str(verdicts([run(True)])) == "1 passed"
    assert str(verdicts([run(False, ["stack_health"])])) == "1 failed (stack_health 1)"


@pytest.mark.parametrize("block", ADDT, ids=ids(ADDT))
def test_addt_example_compiles_as_stated(block, base):
    result = compile_source(source(block), block.doc, base_dir=base)
    what = kind(block)
    if what == "diagnostics":
        got, want = _found(result), expected_diagnostics(block)
        code = section_code(block) if block.doc == "docs/diagnostics.md" else None
        assert want or code, f"{block.name}: state its diagnostics with `# expect: CODE @ line:col`"
        if code in CODES_WITHOUT_MODULE and importlib.util.find_spec(CODES_WITHOUT_MODULE[code]) is not None:
            assert result.ok, result.diagnostics  # E0601 and the like only where the module is missing
        elif code:
            assert code in {c for c, _, _ in got}, (code, result.diagnostics)
        if want:
            assert got == want, result.diagnostics
    elif what == "file":
        assert not any(d.code in ("E0001", "E0002") for d in result.diagnostics), result.diagnostics
        assert any(f'include "{block.attrs.get("file")}"' in b.text for b in ADDT), \
            f"{block.name}: a block of definitions names its file (file=...) and a scenario includes it"
    else:
        assert result.ok and not result.diagnostics, [str(d) for d in result.diagnostics]
        if what == "scenario":
            assert block.attrs.get("expect"), f"{block.name}: state its verdicts: ```addt expect=\"...\""


def test_every_diagnostic_code_has_an_example():
    no_example = {"E0003", "E0004", "E0900"}  # binary input, a very long line, a compiler bug
    # OpenSCENARIO import (XML input): tests/unit/interop/test_xosc_import.py
    no_example |= {"E0801", "E0802", "E0803", "W0801", "W0802", "W0803"}
    shown = {section_code(b) for b in ADDT if b.doc == "docs/diagnostics.md"}
    assert set(CODES) - no_example <= shown


@pytest.mark.parametrize("line", FAULT_LINES)
def test_fault_line_compiles_in_its_wrapper(line, base):
    result = compile_source(fault_scenario(line), "docs/faults.md", base_dir=base)
    assert result.ok, [str(d) for d in result.diagnostics]
    (fault,) = result.plan.faults
    assert fault.kind == kind_of(line)


@pytest.mark.parametrize("block", PYTHON, ids=ids(PYTHON))
def test_python_example_runs(block, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    exec(compile(block.text, f"{ROOT / block.doc}:{block.line}", "exec"), {"__name__": "doc_example"})


COMMANDS = addtc_commands()


def test_there_are_addtc_commands():
    assert len(COMMANDS) >= 12


@pytest.mark.parametrize(("block", "argv"), COMMANDS, ids=[f"{b.doc}:{b.line} {' '.join(a)}" for b, a in COMMANDS])
def test_addtc_command_parses_and_names_scenarios_that_compile(block, argv):
    if argv[0] != "study":
        build_parser().parse_args(argv if argv[0] in SUBCOMMANDS else ["run", *argv])
    # A regen block's commands run (tests/sim/test_docs_regen.py); a recipe's run in a scratch
    # repository of its own (tests/quality/test_ci_recipe.py), not this one.
    if "regen" not in block.attrs and "recipe" not in block.attrs:
        assert_scenarios_compile([a for a in argv if a.endswith(".addt")])
