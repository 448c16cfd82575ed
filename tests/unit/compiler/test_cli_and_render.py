"""`addtc check`: exit codes, rustc-style text, one JSON document; file confinement."""

from __future__ import annotations

import json
import os

import pytest
from tests.unit.compiler.conftest import CASES_DIR, REPO

from addt_dsl.cli import main
from addt_dsl.compiler import compile_file, compile_source
from addt_dsl.diagnostics import render_text

GOOD = REPO / "examples" / "overtake.addt"
BAD = CASES_DIR / "units.addt"


def test_exit_codes(capsys):
    assert main(["check", str(GOOD)]) == 0
    assert main(["check", str(GOOD), str(BAD)]) == 2
    assert main(["check", str(CASES_DIR / "warnings.addt")]) == 0  # warnings do not fail


def test_text_rendering_points_at_the_error():
    result = compile_file(BAD)
    text = render_text(result.diagnostics, result.sources)
    first = text.split("\n\n")[0].splitlines()
    assert first[0] == "error[E0201]: 'at' of the ego needs a length, found a speed"
    assert first[1].endswith("units.addt:9:27")
    source_line = next(line for line in first if line.startswith("9 |"))
    caret_line = first[first.index(source_line) + 1]
    col = caret_line.index("^") - caret_line.index("|") - 1
    assert source_line[source_line.index("|") + 1 + col:].startswith("10 m/s")
    assert caret_line.count("^") == len("10 m/s")
    assert "this is a speed" in caret_line
    assert text.rstrip().endswith("7 error(s), 0 warning(s)")


def test_help_notes_are_rendered_as_help():
    result = compile_source("scenario s {\n  duration 10 s\n  duraton 3 s\n}\n")
    assert "= help: did you mean 'duration'?" in render_text(result.diagnostics, result.sources)


def test_json_is_one_document_for_many_files(capsys):
    assert main(["check", "--format", "json", str(BAD), str(CASES_DIR / "names.addt"), str(GOOD)]) == 2
    data = json.loads(capsys.readouterr().out)
    files = {d["file"] for d in data}
    assert len(files) == 2 and all(f.endswith((".addt")) for f in files)
    first = data[0]
    assert set(first) == {"code", "severity", "message", "file", "line", "col", "end_line", "end_col",
                          "label", "notes"}
    assert first["severity"] in ("error", "warning")


def test_syntax_errors_list_expected_tokens():
    result = compile_source("scenario s {\n  duration 10 s\n  road r { line length }\n}\n")
    (diag,) = result.diagnostics
    assert diag.code == "E0001" and any("expected" in n and "a number" in n for n in diag.notes)


# ---------------------------------------------------------------- confinement

def _scenario(body: str) -> str:
    return f"scenario s {{\n  duration 10 s\n{body}\n}}\n"


def test_symlink_out_of_the_tree_is_rejected(tmp_path):
    outside = tmp_path / "outside.addt"
    outside.write_text("param p = 1\n")
    tree = tmp_path / "tree"
    tree.mkdir()
    os.symlink(outside, tree / "link.addt")
    (tree / "main.addt").write_text('include "link.addt"\n' + _scenario(""))
    codes = {d.code for d in compile_file(tree / "main.addt").diagnostics}
    assert "E0402" in codes


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs FIFOs")
def test_a_fifo_is_not_read(tmp_path):
    os.mkfifo(tmp_path / "pipe.addt")
    (tmp_path / "main.addt").write_text('include "pipe.addt"\n' + _scenario(""))
    codes = {d.code for d in compile_file(tmp_path / "main.addt").diagnostics}
    assert "E0401" in codes  # refused without blocking on the pipe


def test_oversized_include_is_refused_before_reading(tmp_path):
    (tmp_path / "big.addt").write_bytes(b"#" * 1_100_000)
    (tmp_path / "main.addt").write_text('include "big.addt"\n' + _scenario(""))
    diags = compile_file(tmp_path / "main.addt").diagnostics
    assert any(d.code == "E0701" and "source_bytes" in d.message and "--max source_bytes" in d.notes[-1]
               for d in diags)


def test_nested_include_stays_confined_to_the_main_directory(tmp_path):
    (tmp_path / "lib").mkdir()
    (tmp_path / "lib" / "a.addt").write_text('include "../../escape.addt"\n')
    (tmp_path / "main.addt").write_text('include "lib/a.addt"\n' + _scenario(""))
    codes = {d.code for d in compile_file(tmp_path / "main.addt").diagnostics}
    assert "E0402" in codes


def test_directory_and_missing_file(tmp_path):
    assert compile_file(tmp_path).diagnostics[0].code == "E0401"
    assert compile_file(tmp_path / "nope.addt").diagnostics[0].code == "E0401"


def test_diamond_includes_are_read_once_so_work_stays_linear(tmp_path, monkeypatch):
    # Each level includes the next one twice: without include-once this is 2**15 reads and parses.
    from collections import Counter

    from addt_dsl import compiler as C

    for i in range(15):
        (tmp_path / f"l{i}.addt").write_text(f'include "l{i + 1}.addt"\ninclude "l{i + 1}.addt"\n')
    (tmp_path / "l15.addt").write_text("param shared = 1 m\n")
    (tmp_path / "main.addt").write_text('include "l0.addt"\n' + _scenario(
        "  road r { line length 100 m }\n  ego car on r lane -1 at shared"))
    reads = Counter()
    real = C._Loader.read_bytes
    monkeypatch.setattr(C._Loader, "read_bytes",
                        lambda self, path, *a: reads.update([path.name]) or real(self, path, *a))
    result = compile_file(tmp_path / "main.addt")
    assert result.ok, result.diagnostics
    assert {f"l{i}.addt": 1 for i in range(16)} == {k: v for k, v in reads.items() if k.startswith("l")}
    assert [p.name for p in result.plan.params].count("shared") == 1  # its definition came in once


def test_imports_of_one_file_are_read_and_parsed_once(tmp_path, monkeypatch):
    import shutil

    from addt_dsl.compiler import xodr_check as road

    shutil.copy(REPO / "examples" / "maps" / "straight_500m.xodr", tmp_path / "map.xodr")
    roads = "\n".join(f'  road r{i} import "map.xodr"' for i in range(50))
    (tmp_path / "main.addt").write_text(_scenario(roads + "\n  ego car on r0 lane -1 at 10 m"))
    calls = []
    real = road.parse_xodr
    monkeypatch.setattr(road, "parse_xodr", lambda *a, **k: calls.append(1) or real(*a, **k))
    result = compile_file(tmp_path / "main.addt")
    assert result.ok, result.diagnostics
    assert len(calls) == 1 and len(result.plan.roads) == 50
