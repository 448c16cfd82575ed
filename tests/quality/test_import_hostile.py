"""Hostile and damaged OpenSCENARIO files end within their limits with a diagnostic, never an
internal error: a parameter-expansion bomb, a file without <Init>, positions no road has,
and many catalog references (each catalog file read once)."""

from __future__ import annotations

import re
import shutil
import time
from pathlib import Path

import pytest

from addt_dsl.cli import main
from addt_dsl.interop.openscenario.importer import import_xosc
from addt_dsl.interop.openscenario.reader import Importer

ROOT = Path(__file__).resolve().parents[2]
ESMINI = ROOT / "tests" / "data" / "esmini"
SOURCE = (ESMINI / "xosc" / "cut-in_simple.xosc").read_text()


@pytest.fixture
def tree(tmp_path):
    shutil.copytree(ESMINI / "xodr", tmp_path / "xodr")
    shutil.copytree(ESMINI / "xosc" / "Catalogs", tmp_path / "xosc" / "Catalogs")
    return tmp_path


def _write(tree: Path, name: str, text: str) -> Path:
    path = tree / "xosc" / name
    path.write_text(text)
    return path


def test_a_parameter_expansion_bomb_ends_in_seconds(tree, capsys):
    # 7 levels, each parameter 30 references to the one before: 30^7 expansions one by one.
    decls = ['<ParameterDeclaration name="p0" parameterType="string" value="1"/>']
    for i in range(1, 8):
        decls.append(f'<ParameterDeclaration name="p{i}" parameterType="string" value="${{'
                     + " + ".join([f"$p{i - 1}"] * 30) + '}"/>')
    text = SOURCE.replace("<ParameterDeclarations>", "<ParameterDeclarations>" + "".join(decls), 1)
    text = text.replace('value="20"', 'value="$p7"', 1)
    path = _write(tree, "bomb.xosc", text)
    start = time.perf_counter()
    code = main(["import", str(path), "--root", str(tree)])
    assert time.perf_counter() - start < 20.0
    assert code == 2 and "internal error" not in capsys.readouterr().err


def test_a_file_without_init_imports_with_its_defaults(tree):
    path = _write(tree, "noinit.xosc", re.sub(r"<Init>.*?</Init>", "", SOURCE, flags=re.S))
    got = import_xosc(path, root=tree, lenient=True)
    assert got.plan is not None, [d.message for d in got.diagnostics if d.is_error]
    assert any("no translated initial position" in d.message for d in got.diagnostics)


@pytest.mark.parametrize("old, new", [('s="50"', 's="1e308"'), ('laneId="-1"', 'laneId="2147483648"')])
def test_a_place_no_road_has_is_invalid_content(tree, capsys, old, new):
    path = _write(tree, "far.xosc", SOURCE.replace(old, new, 1))
    assert main(["import", str(path), "--root", str(tree)]) == 2
    err = capsys.readouterr().err
    assert "E0802" in err and "not a place on any road" in err and "internal error" not in err


def test_each_catalog_file_is_read_once(tree, monkeypatch):
    reads: list[str] = []
    real = Importer.read

    def counting(self, relative, base, el, *args, **kwargs):
        reads.append(relative)
        return real(self, relative, base, el, *args, **kwargs)

    monkeypatch.setattr(Importer, "read", counting)
    got = import_xosc(ESMINI / "xosc" / "highway_merge.xosc", root=ESMINI, lenient=True)
    assert got.plan is not None
    catalogs = [r for r in reads if "Catalogs" in r]
    assert catalogs and len(catalogs) == len(set(catalogs)), catalogs
