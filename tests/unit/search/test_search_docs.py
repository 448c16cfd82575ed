"""docs/falsify-and-shrink.md and docs/ci.md: their examples compile, parse and use real options."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

from addt_dsl.cli import build_parser
from addt_dsl.compiler import compile_source
from addt_dsl.printer import compile_pinned
from addt_dsl.pytest_plugin import pytest_addoption

DOCS = Path(__file__).resolve().parents[3] / "docs"
SHRINK_DOC = (DOCS / "falsify-and-shrink.md").read_text()
CI_DOC = (DOCS / "ci.md").read_text()


def _blocks(text: str, lang: str) -> list[str]:
    return re.findall(rf"```{lang}[^\n]*\n(.*?)```", text, re.S)


def _commands(program: str) -> list[list[str]]:
    lines = []
    for text in (SHRINK_DOC, CI_DOC):
        for block in _blocks(text, "console"):
            lines += [line[2:] for line in block.splitlines() if line.startswith(f"$ {program} ")]
        for block in _blocks(text, "yaml"):
            lines += re.findall(rf"(?:run:|- ) *({program} [^\n]+)", block)
    return [shlex.split(line)[1:] for line in lines]


class _Options:
    def __init__(self):
        self.options, self.ini = set(), set()

    def getgroup(self, *args):
        return self

    def addoption(self, *names, **kwargs):
        self.options.update(names)

    def addini(self, name, *args, **kwargs):
        self.ini.add(name)


def _plugin_options() -> _Options:
    opts = _Options()
    pytest_addoption(opts)
    return opts


def test_the_pinned_example_compiles_to_one_pinned_run():
    (block,) = _blocks(SHRINK_DOC, "addt")  # docs/regen.py writes it; its seeds and window are read back
    spec = compile_pinned(block)
    assert spec.seed == int(re.search(r"run_seed (\d+)", block).group(1))
    start, end, seed = re.search(r"during \[(\S+) s, (\S+) s\] stuck control.accel value 3 seed (\d+)", block).groups()
    assert [(f.kind, f.target, f.start_s, f.end_s, f.seed) for f in spec.faults] == \
        [("stuck", "control.accel", float(start), float(end), int(seed))]
    assert compile_source(block).ok


@pytest.mark.parametrize("argv", _commands("addtc"), ids=" ".join)
def test_addtc_commands_parse(argv):
    args = build_parser().parse_args(argv)
    assert args.command in ("shrink", "falsify", "run")


def test_there_are_pytest_commands():
    assert len(_commands("pytest")) >= 3


@pytest.mark.parametrize("argv", _commands("pytest"), ids=" ".join)
def test_pytest_commands_use_real_options(argv):
    opts = _plugin_options()
    from hypothesis import settings

    for i, arg in enumerate(argv):
        name = arg.split("=", 1)[0]
        if name.startswith("--addt"):
            assert name in opts.options, name
        if name == "--hypothesis-profile":
            settings.get_profile(argv[i + 1])


def test_documented_options_exist():
    opts = _plugin_options()
    for flag in set(re.findall(r"`(--addt-[a-z-]+)", CI_DOC)):
        assert flag in opts.options, flag
    for ini in set(re.findall(r"\((addt_[a-z_]+)", CI_DOC)) | set(re.findall(r"`(addt_[a-z_]+) =", CI_DOC)):
        assert ini in opts.ini, ini


def test_ci_jobs_are_valid_yaml():
    yaml = pytest.importorskip("yaml")  # pyyaml: in the test extra through ray
    github, gitlab = (yaml.safe_load(b) for b in _blocks(CI_DOC, "yaml"))
    steps = github["jobs"]["scenarios"]["steps"]
    assert any("pytest scenarios/" in s.get("run", "") for s in steps)
    assert any(s.get("with", {}).get("path") == ".addt-failures/" for s in steps)
    assert gitlab["scenarios"]["artifacts"]["reports"]["junit"] == "scenario-report.xml"
    assert ".addt-failures/" in gitlab["scenarios"]["artifacts"]["paths"]


def test_the_samplers_table_is_the_registry():
    """The table between its regen markers is what `python -m addt_dsl.search.samplers` prints
    (docs/regen.py rewrites it; this checks without running the doc's other commands)."""
    from addt_dsl.search.samplers import markdown_table
    from docs.regen import _SECTION

    command = "python -m addt_dsl.search.samplers"
    section = next(m for m in _SECTION.finditer(SHRINK_DOC) if m.group("command") == command)
    assert section.group("body") == markdown_table()
    assert "| `cmaes` |" in section.group("body")
