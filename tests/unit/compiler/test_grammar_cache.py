"""The built parser is cached on disk (building it took longer than compiling a
hundred files). A cached parser parses exactly like a fresh one; a changed grammar, lark or
Python version gets a new cache file; a damaged file is rebuilt, never trusted."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

from tests.unit.compiler.conftest import REPO

from addt_dsl.compiler import parser as P

SCRIPT = textwrap.dedent("""
    import json, sys, time
    from addt_dsl.compiler import compile_file
    from addt_dsl.compiler import parser as P
    from addt_dsl.diagnostics import render_json
    t0 = time.perf_counter()
    P._parser()
    built = time.perf_counter() - t0
    r = compile_file(sys.argv[1])
    bad = compile_file(sys.argv[2])
    print(json.dumps({"built_s": built, "plan": r.plan.model_dump_json(),
                      "diags": render_json(bad.diagnostics)}))
""")


def _run(cache_dir, good, bad) -> dict:
    env = dict(os.environ, ADDT_GRAMMAR_CACHE=str(cache_dir), PYTHONPATH=str(REPO))
    out = subprocess.run([sys.executable, "-c", SCRIPT, str(good), str(bad)], env=env, cwd=REPO,
                         capture_output=True, text=True, check=True)
    assert out.stderr == ""  # lark logs nothing (no failed load or write)
    return json.loads(out.stdout)


def test_cached_parser_compiles_like_a_fresh_one(tmp_path):
    good = REPO / "examples" / "overtake.addt"
    bad = tmp_path / "bad.addt"
    bad.write_text("scenario s {\n  duration 10 s\n  param p = 1 m in [0 m 2 m]\n  agent x car at\n}\n")
    off = _run("off", good, bad)
    first = _run(tmp_path / "cache", good, bad)  # builds and writes the cache
    files = list((tmp_path / "cache").iterdir())
    assert [f.name for f in files] == [P.grammar_cache_file("start", tmp_path / "cache").name]
    second = _run(tmp_path / "cache", good, bad)  # loads it
    assert off["plan"] == first["plan"] == second["plan"]
    assert off["diags"] == first["diags"] == second["diags"] and off["diags"]
    # A damaged cache file is not trusted: lark checks the digest inside and rebuilds.
    files[0].write_bytes(b"0" * 64 + b"\n" + files[0].read_bytes()[65:])
    third = _run(tmp_path / "cache", good, bad)
    assert third["plan"] == off["plan"] and third["diags"] == off["diags"]


def test_the_cache_file_name_follows_the_grammar(tmp_path, monkeypatch):
    name = P.grammar_cache_file("start", tmp_path)
    assert name == P.grammar_cache_file("start", tmp_path)
    assert name != P.grammar_cache_file("expr", tmp_path)
    changed = tmp_path / "addt.lark"
    changed.write_text(P.GRAMMAR_PATH.read_text() + "\n// one more comment\n")
    monkeypatch.setattr(P, "GRAMMAR_PATH", changed)
    assert P.grammar_cache_file("start", tmp_path) != name


def test_the_cache_directory(monkeypatch, tmp_path):
    monkeypatch.setenv(P.CACHE_ENV, "off")
    assert P.grammar_cache_dir() is None
    monkeypatch.setenv(P.CACHE_ENV, str(tmp_path))
    assert P.grammar_cache_dir() == tmp_path
    monkeypatch.delenv(P.CACHE_ENV)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert P.grammar_cache_dir() == tmp_path / "xdg" / "addt-dsl"
