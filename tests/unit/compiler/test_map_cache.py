"""Imported OpenDRIVE maps are parsed once per process while their content stays the same
(a suite's files import the same few maps). Correctness first: an edited map is
parsed again, a broken one reports on every compilation, and results equal a cold compile."""

from __future__ import annotations


import pytest
from tests.unit.compiler.conftest import REPO

from addt_dsl.compiler import compile_file
from addt_dsl.compiler import xodr_check as X
from addt_dsl.diagnostics import render_json
from addt_dsl.lru import LruCache

MAP_EXAMPLES = sorted(p for p in (REPO / "examples").glob("*.addt") if 'import "maps/' in p.read_text())


@pytest.fixture
def counted(monkeypatch):
    calls = []
    real = X.parse_xodr

    def spy(text, display):
        calls.append(display)
        return real(text, display)

    monkeypatch.setattr(X, "parse_xodr", spy)
    monkeypatch.setattr(X, "_MAPS", LruCache(X.MAP_CACHE_SIZE, on_evict=X._MAPS.on_evict))
    monkeypatch.setattr(X, "_INFOS", {})
    return calls


def _same(a, b) -> None:
    assert (a.plan is None) == (b.plan is None)
    if a.plan is not None:
        assert a.plan.model_dump_json() == b.plan.model_dump_json()
    assert render_json(a.diagnostics) == render_json(b.diagnostics)


def test_examples_compile_the_same_from_the_cache(counted):
    assert MAP_EXAMPLES
    cold = [compile_file(p) for p in MAP_EXAMPLES]
    parses = len(counted)
    warm = [compile_file(p) for p in MAP_EXAMPLES]
    assert len(counted) == parses  # no map parsed again
    assert parses == len({p.read_text().split('import "')[1].split('"')[0] for p in MAP_EXAMPLES})
    for a, b in zip(cold, warm):
        _same(a, b)


SCENARIO = """scenario s {{
  duration 5 s
  road town import "town.xodr" road {road}
  ego car on town lane -1 at 5 m speed 5 m/s
}}
"""
ROAD = ('<road name="" length="200" id="{i}" junction="-1"><planView><geometry s="0" x="0" y="{y}" hdg="0" '
        'length="200"><line/></geometry></planView><lanes><laneSection s="0"><center><lane id="0" type="none"/>'
        '</center><right><lane id="-1" type="driving"><width sOffset="0" a="{w}" b="0" c="0" d="0"/></lane>'
        '</right></laneSection></lanes></road>')


def _map(roads: int, width: float = 3.5) -> str:
    body = "".join(ROAD.format(i=i + 1, y=20 * i, w=width) for i in range(roads))
    return f'<?xml version="1.0"?>\n<OpenDRIVE><header revMajor="1" revMinor="4"/>{body}</OpenDRIVE>\n'


def test_an_edited_map_is_parsed_again(tmp_path, counted):
    main = tmp_path / "s.addt"
    main.write_text(SCENARIO.format(road=2))
    (tmp_path / "town.xodr").write_text(_map(2))
    assert compile_file(main).ok and compile_file(main).ok
    assert len(counted) == 1
    (tmp_path / "town.xodr").write_text(_map(1))  # road 2 is gone
    gone = compile_file(main)
    assert not gone.ok and any("has no road '2'" in d.message for d in gone.diagnostics)
    assert len(counted) == 2
    (tmp_path / "town.xodr").write_text(_map(2, width=2.5))  # narrower lanes: new shapes, not the old ones
    narrow = compile_file(main)
    assert narrow.ok and len(counted) == 3


def test_a_broken_map_reports_every_time(tmp_path, counted):
    main = tmp_path / "s.addt"
    main.write_text(SCENARIO.format(road=1))
    (tmp_path / "town.xodr").write_text(_map(1).replace("</OpenDRIVE>", ""))
    first, second = compile_file(main), compile_file(main)
    assert not first.ok and render_json(first.diagnostics) == render_json(second.diagnostics)
    assert len(counted) == 2


def test_the_map_cache_is_bounded(tmp_path, counted, monkeypatch):
    X._MAPS.size = 2  # `counted` gave this test its own cache
    for n in range(1, 5):
        X.parsed_map(_map(n), "m.xodr")
    assert len(X._MAPS) == 2 and len(X._INFOS) == 2
    X.parsed_map(_map(4), "m.xodr")
    assert len(counted) == 4


INLINE = """scenario s {{
  duration 5 s
  road r {{
    line length {length} m
    lanes right 2 width 3.5 m
  }}
  ego car on r lane -1 at 5 m speed 5 m/s
}}
"""


def test_inline_road_verdicts_are_kept_per_road(tmp_path, monkeypatch):
    """An inline road is built once per distinct plan; a road that cannot be built is
    reported on every compilation, at its own file's span."""
    built = []
    real = X.build_network
    monkeypatch.setattr(X, "build_network", lambda plans: built.append(plans) or real(plans))
    monkeypatch.setattr(X, "_INLINE", LruCache(X.INLINE_CACHE_SIZE))
    for i in range(3):
        (tmp_path / f"a{i}.addt").write_text(INLINE.format(length=300))
    assert all(compile_file(tmp_path / f"a{i}.addt").ok for i in range(3))
    assert len(built) == 1
    (tmp_path / "b.addt").write_text(INLINE.format(length=400))
    assert compile_file(tmp_path / "b.addt").ok and len(built) == 2
    (tmp_path / "huge.addt").write_text(INLINE.format(length="1e9"))
    (tmp_path / "huge2.addt").write_text("\n" + INLINE.format(length="1e9"))
    first, second = compile_file(tmp_path / "huge.addt"), compile_file(tmp_path / "huge2.addt")
    assert not first.ok and not second.ok
    e1 = [d for d in first.diagnostics if d.code == "E0301"]
    e2 = [d for d in second.diagnostics if d.code == "E0301"]
    assert e1 and e2 and e1[0].message == e2[0].message
    assert e2[0].span.line == e1[0].span.line + 1 and e2[0].span.file.endswith("huge2.addt")
