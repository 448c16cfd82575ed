"""Error recovery: every broken statement is reported, each on its own line, and the
statements around it are not blamed."""

from __future__ import annotations

import pytest
from tests.unit.compiler.conftest import CASES_DIR, REPO, describe
from hypothesis import given, settings
from hypothesis import strategies as st

from addt_dsl.compiler import compile_source

VALID = [REPO / "examples" / "overtake.addt", CASES_DIR / "ok_full.addt", CASES_DIR / "include_ok.addt"]


@pytest.mark.parametrize("path", VALID, ids=lambda p: p.stem)
@settings(max_examples=40, deadline=None)
@given(data=st.data())
def test_each_corrupted_line_is_reported_and_only_those(path, data):
    lines = path.read_text().split("\n")
    candidates = [i for i, line in enumerate(lines) if line.strip() and not line.strip().startswith("#")]
    chosen = data.draw(st.sets(st.sampled_from(candidates), min_size=1, max_size=6))
    corrupt = data.draw(st.sampled_from([" @", " ;", " = =", " ) ", " ]"]))
    broken = [line + corrupt if i in chosen else line for i, line in enumerate(lines)]
    result = compile_source("\n".join(broken), path.name, base_dir=path.parent)
    reported = {d.span.line for d in result.diagnostics if d.code in ("E0001", "E0002")}
    assert reported == {i + 1 for i in chosen}, describe(result)
    assert all(d.code in ("E0001", "E0002") for d in result.diagnostics)


@pytest.mark.parametrize("block", ["road highway {", "ego car on highway", "agent lead car", "faults {",
                                   "expect {"])
def test_a_missing_closing_brace_is_one_error_naming_the_open_block(block):
    lines = (REPO / "examples" / "overtake.addt").read_text().split("\n")
    start = next(i for i, line in enumerate(lines) if line.strip().startswith(block))
    end = next(i for i in range(start, len(lines)) if lines[i].strip() == "}")
    broken = "\n".join(lines[:end] + lines[end + 1:])
    result = compile_source(broken, "overtake.addt")
    assert len(result.diagnostics) == 1, describe(result)
    (diag,) = result.diagnostics
    assert diag.code == "E0001" and f"overtake.addt:{start + 1}:" in diag.notes[0], describe(result)


@pytest.mark.parametrize("typo,meant", [("expcet", "expect"), ("sweeps", "sweep"), ("fautls", "faults"),
                                        ("enviroment", "environment"), ("light", "lights")])
def test_a_misspelt_block_keyword_names_the_block_meant(typo, meant):
    """`expcet {` was a raw parser error at '{' listing tokens; it is E0005 on the word, with
    the block meant."""
    text = (REPO / "examples" / "overtake.addt").read_text()
    opener = {"expect": "expect {", "sweep": "sweep {", "faults": "faults {", "environment": "expect {",
              "lights": "expect {"}[meant]
    line = next(i for i, t in enumerate(text.split("\n")) if t.strip() == opener) + 1
    broken = text.replace(opener, f"{typo} {{", 1)
    result = compile_source(broken, "overtake.addt", base_dir=REPO / "examples")
    assert [d.code for d in result.diagnostics] == ["E0005"], describe(result)
    (diag,) = result.diagnostics
    assert (diag.span.line, diag.span.end_col - diag.span.col) == (line, len(typo))
    assert f"did you mean `{meant}`?" in diag.notes
    assert not any("expected" in n for n in diag.notes)


def test_a_named_step_in_lights_says_only_actor_steps_have_names():
    text = """scenario t {
  duration 5 s
  road main {
    line length 300 m
    lanes right 2
  }
  lights {
    controller west signals [1] green 2 s yellow 2 s red 30 s
    to_red: at 3 s light west state red
  }
  ego car on main lane -1 at 10 m speed 10 m/s goal 100 m
}
"""
    result = compile_source(text, "t.addt")
    assert [d.code for d in result.diagnostics] == ["E0001"], describe(result)
    (diag,) = result.diagnostics
    assert "cannot be named" in diag.message and (diag.span.line, diag.span.col) == (9, 5)
    assert "write `at 3 s light west state red`" in diag.notes
    assert not any(n.startswith("expected") for n in diag.notes)
