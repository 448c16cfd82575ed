"""Hostile inputs: each is refused with its diagnostic at its file:line:col, in
bounded time, never with an internal error (E0900). Data files in hostile/ state their
expected diagnostics (`# expect: CODE @ line:col`); the file-system cases (over-long names,
symlink loops, suite members that lead out) are built in a temporary directory."""

from __future__ import annotations

import os
import shutil
import time
from pathlib import Path

import pytest
from tests.unit.compiler.conftest import EXPECT_RE

from addt_dsl.compiler import compile_file
from addt_dsl.diagnostics import render_text
from addt_dsl.suite import SuiteError, expand_paths

HOSTILE = Path(__file__).resolve().parent / "hostile"
TIME_BOUND_S = 10.0  # generous for a loaded CI machine; each case takes well under a second

SCENARIO = """scenario s {{
  duration 10 s
  road r {{
    line length 400 m
    lanes right 2 width 3.5 m
  }}
  {extra}
  ego car on r lane -1 at 20 m speed 10 m/s
}}
"""


def _compile(path: Path):
    t0 = time.monotonic()
    result = compile_file(path)
    assert time.monotonic() - t0 < TIME_BOUND_S
    assert "E0900" not in {d.code for d in result.diagnostics}, render_text(result.diagnostics, result.sources)
    assert not result.ok
    return result


@pytest.mark.parametrize("name", sorted(p.name for p in HOSTILE.glob("*.addt")))
def test_hostile_file_gets_its_diagnostic(name):
    path = HOSTILE / name
    expected = {(c, int(ln), int(col)) for c, ln, col in EXPECT_RE.findall(path.read_text())}
    assert expected, f"{name} states no expectation"
    result = _compile(path)
    assert {(d.code, d.span.line, d.span.col) for d in result.diagnostics if d.span} == expected


@pytest.mark.parametrize("name, limit", [
    ("map_arc_curvature.addt", "MAX_GEOMETRY_TURN_RAD"), ("map_spiral_curvature.addt", "MAX_GEOMETRY_TURN_RAD"),
    ("map_long_road.addt", "MAX_ROAD_LENGTH_M"), ("map_lane_width.addt", "MAX_LANE_WIDTH_M"),
    ("map_poly3_bend.addt", "MAX_ROAD_SAMPLES"), ("map_far_reach.addt", "MAX_COORDINATE_M"),
])
def test_map_limits_are_named_with_the_xml_line(name, limit):
    (d,) = _compile(HOSTILE / name).diagnostics
    assert limit in d.message and "limits.py" in d.message
    assert any(n.startswith("at ") and ".xodr:" in n for n in d.notes)


def test_an_over_long_include_or_import_name(tmp_path):
    long = "x" * 300
    for line in (f'include "{long}.addt"', ""):
        extra = "" if line else f'road q import "{long}.xodr"'
        src = tmp_path / "s.addt"
        src.write_text(line + "\n" + SCENARIO.format(extra=extra))
        (d,) = _compile(src).diagnostics
        assert d.code == "E0401" and "too long" in d.message and d.span.line == (1 if line else 8)


def test_includes_that_are_symlinks_to_each_other(tmp_path):
    os.symlink("b.addt", tmp_path / "a.addt")
    os.symlink("a.addt", tmp_path / "b.addt")
    src = tmp_path / "s.addt"
    src.write_text('include "a.addt"\n' + SCENARIO.format(extra=""))
    (d,) = _compile(src).diagnostics
    assert (d.code, d.span.line, d.span.col) == ("E0401", 1, 1) and "loop" in d.message


def test_confinement_notes_show_no_absolute_path(tmp_path):
    src = tmp_path / "s.addt"
    src.write_text('include "missing.addt"\ninclude "../x.addt"\ninclude "/etc/hostname"\n' + SCENARIO.format(extra=""))
    result = _compile(src)
    assert [d.code for d in result.diagnostics] == ["E0401", "E0402", "E0402"]
    for d in result.diagnostics:
        assert str(tmp_path) not in " ".join((d.message, *d.notes))


def test_suite_member_symlink_leading_out_is_refused_unread(tmp_path):
    secret = tmp_path / "secret.txt"
    secret.write_text("top secret first line\n")
    suite = tmp_path / "suite"
    suite.mkdir()
    (suite / "ok.addt").write_text(SCENARIO.format(extra=""))
    os.symlink(secret, suite / "evil.addt")
    with pytest.raises(SuiteError, match="outside") as err:
        expand_paths([str(suite)])
    assert "top secret" not in str(err.value)
    os.remove(suite / "evil.addt")
    os.symlink("loop.addt", suite / "loop.addt")
    with pytest.raises(SuiteError, match="loop"):
        expand_paths([str(suite)])
    os.remove(suite / "loop.addt")
    assert expand_paths([str(suite)]) == [suite / "ok.addt"]


def test_no_diagnostic_text_shows_an_absolute_path(tmp_path):
    """Every hostile case compiled from outside the working directory, named absolutely:
    messages and notes name its files relative to the scenario's directory."""
    copy = tmp_path / "hostile"
    shutil.copytree(HOSTILE, copy)
    for path in sorted(copy.glob("*.addt")):
        for d in _compile(path).diagnostics:
            assert str(tmp_path) not in " ".join((d.message, *d.notes)), (path.name, d)


def test_twenty_includes_of_a_megabyte_are_refused_unparsed(tmp_path):
    block = ("param p = 1 m in [0 m, 2 m]\n" * 40_000)[: 1 << 20]
    for k in range(20):
        (tmp_path / f"big{k}.addt").write_text(block)
    src = tmp_path / "s.addt"
    src.write_text("".join(f'include "big{k}.addt"\n' for k in range(20)) + SCENARIO.format(extra=""))
    diags = _compile(src).diagnostics
    assert [(d.code, d.span.line) for d in diags] == [("E0701", k + 1) for k in range(20)]
    assert all("source_bytes" in d.message and "--max source_bytes=N" in d.notes[-1] for d in diags)


def test_a_map_of_too_many_roads_is_refused_before_it_is_built(tmp_path):
    road = '<road length="10" id="{i}" junction="-1"><planView><geometry s="0" x="0" y="{i}" hdg="0" ' \
           'length="10"><line/></geometry></planView></road>\n'
    roads = "".join(road.format(i=i) for i in range(1, 20_002))
    (tmp_path / "big.xodr").write_text(f'<?xml version="1.0"?><OpenDRIVE><header revMajor="1" revMinor="4"/>\n'
                                       f'{roads}</OpenDRIVE>\n')
    src = tmp_path / "s.addt"
    src.write_text(SCENARIO.format(extra='road q import "big.xodr"'))
    (d,) = _compile(src).diagnostics
    assert d.code == "E0701" and "roads_per_map" in d.message and "20,001" in d.message and d.span.line == 7
