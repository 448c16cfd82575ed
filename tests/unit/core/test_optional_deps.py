"""Without torch (the core install), a scenario or command that needs it is told so in one
clear message, never an ImportError; the compiler never imports torch to find out.

`sys.modules["torch"] = None` hides an installed torch from `importlib.util.find_spec`
(it returns None), so these tests see the core install's behaviour in any environment."""

import re
import subprocess
import sys
import textwrap

import pytest

from addt_dsl import extras
from addt_dsl.compiler import compile_source
from addt_dsl.diagnostics import render_text
from tests.conftest import EXAMPLES, ROOT

LEARNED = EXAMPLES / "suites" / "shift_yaw_learned.addt"
SOURCE = """\
scenario s {
  duration 10 s
  road r { line length 300 m }
  ego car on r lane -1 at 10 m speed 10 m/s {
    stack bev perception learned
    sensor lidar rate 10 Hz rays 360 channels 5 vfov 12 deg range 80 m
  }
}
"""


def _without_torch(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", "import sys; sys.modules['torch'] = None\n" + textwrap.dedent(code)],
                          capture_output=True, text=True, cwd=ROOT, timeout=120)


def test_learned_perception_without_torch_is_a_diagnostic_at_the_setting(monkeypatch):
    monkeypatch.setattr(extras, "missing", lambda module: module == "torch")
    result = compile_source(SOURCE, "s.addt")
    assert not result.ok
    [d] = result.diagnostics
    assert (d.code, d.span.line, d.span.col, d.span.end_col) == ("E0601", 5, 15, 33)
    assert extras.EXTRAS["torch"].install in d.notes[0]
    text = render_text(result.diagnostics, result.sources)
    assert "--> s.addt:5:15" in text and "^^^^^^^^^^^^^^^^^^" in text and "= help: add the `learned` extra" in text


def test_the_diagnostics_doc_example_produces_e0601_without_torch(monkeypatch):
    # tests/unit/compiler/test_docs.py cannot check this example: it needs torch missing.
    section = (ROOT / "docs" / "diagnostics.md").read_text(encoding="utf-8").split("### E0601", 1)[1]
    example = re.search(r"```addt\n(.*?)```", section, re.S).group(1)
    monkeypatch.setattr(extras, "missing", lambda module: module == "torch")
    assert [d.code for d in compile_source(example, "E0601.addt").diagnostics] == ["E0601"]


def test_with_torch_installed_the_same_source_compiles(monkeypatch):
    monkeypatch.setattr(extras, "missing", lambda module: False)
    assert compile_source(SOURCE, "s.addt").ok


def test_ground_truth_perception_needs_nothing_outside_the_core_install(monkeypatch):
    monkeypatch.setattr(extras, "missing", lambda module: True)
    assert compile_source(SOURCE.replace("perception learned", "perception ground_truth"), "s.addt").ok


def test_addtc_without_torch_reports_e0601_and_exits_2():
    proc = _without_torch(f"""
        from addt_dsl.cli import main
        sys.exit(main([{str(LEARNED)!r}]))
    """)
    assert proc.returncode == 2, proc.stderr
    assert "error[E0601]: `perception learned` needs torch" in proc.stderr
    assert "Traceback" not in proc.stderr and "ImportError" not in proc.stderr


def test_compiling_a_learned_scenario_does_not_import_torch():
    proc = subprocess.run([sys.executable, "-c", textwrap.dedent(f"""
        import sys
        from addt_dsl.compiler import compile_file
        compile_file({str(LEARNED)!r})
        print("torch" in sys.modules)
    """)], capture_output=True, text=True, cwd=ROOT, timeout=120, check=True)
    assert proc.stdout.strip() == "False"


@pytest.mark.parametrize("module", ["train", "evaluate", "calibrate"])
def test_torch_commands_without_torch_print_one_line_and_exit_2(module):
    proc = _without_torch(f"""
        from addt_dsl.stack.{module} import main
        sys.exit(main([]))
    """)
    assert proc.returncode == 2, proc.stderr
    assert proc.stdout == "" and len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert "needs torch" in proc.stderr and extras.EXTRAS["torch"].install in proc.stderr
