"""Included files are parsed once per process while their content stays the same (a
suite's files include shared definitions). Correctness first: an edited include is parsed
again, a broken one reports its errors on every compilation, and the cache is bounded."""

from __future__ import annotations

import pytest

from addt_dsl.compiler import compile_file
from addt_dsl.compiler import parser as P
from addt_dsl.diagnostics import render_json
from addt_dsl.lru import LruCache

MAIN = """include "shared.addt"
scenario s {{
  duration 5 s
  road r {{
    line length 300 m
    lanes right 2 width 3.5 m
  }}
  ego car on r lane -1 at 20 m speed {speed} m/s
  agent lead car on r lane -1 at 60 m speed lead_speed
}}
"""
SHARED = "param lead_speed = {v} m/s in [5 m/s, 30 m/s]\n"


@pytest.fixture
def counted(monkeypatch):
    """Counts the parses of files named shared.addt."""
    calls = []
    real = P.parse_source

    def spy(data, path, sink, max_bytes=P.MAX_SOURCE_BYTES):
        if path.endswith("shared.addt"):
            calls.append(path)
        return real(data, path, sink, max_bytes)

    monkeypatch.setattr(P, "parse_source", spy)
    monkeypatch.setattr(P, "_INCLUDED", LruCache(P.INCLUDE_CACHE_SIZE))
    return calls


def _lead_speed(result) -> float:
    return next(p for p in result.plan.params if p.name == "lead_speed").default


def test_an_include_is_parsed_once_while_it_is_unchanged(tmp_path, counted):
    (tmp_path / "shared.addt").write_text(SHARED.format(v=12))
    results = []
    for i in range(3):
        main = tmp_path / f"m{i}.addt"
        main.write_text(MAIN.format(speed=10 + i))
        results.append(compile_file(main))
    assert all(r.ok for r in results), [render_json(r.diagnostics) for r in results]
    assert len(counted) == 1
    assert [_lead_speed(r) for r in results] == [12.0] * 3


def test_an_edited_include_is_parsed_again(tmp_path, counted):
    main = tmp_path / "m.addt"
    main.write_text(MAIN.format(speed=10))
    (tmp_path / "shared.addt").write_text(SHARED.format(v=12))
    assert _lead_speed(compile_file(main)) == 12.0
    (tmp_path / "shared.addt").write_text(SHARED.format(v=17))  # same size, same second: content decides
    assert _lead_speed(compile_file(main)) == 17.0
    (tmp_path / "shared.addt").write_text(SHARED.format(v=12))  # back: the first parse serves again
    assert _lead_speed(compile_file(main)) == 12.0
    assert len(counted) == 2


def test_a_broken_include_reports_every_time(tmp_path, counted):
    main = tmp_path / "m.addt"
    main.write_text(MAIN.format(speed=10))
    (tmp_path / "shared.addt").write_text("param lead_speed = 12 m/s in [5 m/s 30 m/s]\n")
    first, second = compile_file(main), compile_file(main)
    assert not first.ok and not second.ok
    assert render_json(first.diagnostics) == render_json(second.diagnostics)
    assert any(d.span and d.span.file.endswith("shared.addt") for d in second.diagnostics)
    assert len(counted) == 2  # not kept: parsed (and reported) each time


def test_the_cache_is_bounded(tmp_path, counted, monkeypatch):
    monkeypatch.setattr(P, "_INCLUDED", LruCache(2))
    sink = P.DiagnosticSink()
    for v in range(5):
        assert P.parse_included(SHARED.format(v=v).encode(), "shared.addt", sink) is not None
    assert len(P._INCLUDED) == 2 and not sink.items
    P.parse_included(SHARED.format(v=4).encode(), "shared.addt", sink)  # the newest is kept
    assert len(counted) == 5
