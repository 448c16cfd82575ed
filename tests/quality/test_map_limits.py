"""`addtc map` applies the compiler's map limits before it builds anything (a 100 MB map took
161 s and 3.1 GB before): too large a file, too many roads, exit 2 with the limit's name."""

from __future__ import annotations

import time

from addt_dsl.cli import main


def _many_roads(path, n: int) -> None:
    path.write_text('<?xml version="1.0"?><OpenDRIVE><header/>'
                    + "".join(f'<road id="{i}" length="1" junction="-1"></road>' for i in range(n))
                    + "</OpenDRIVE>")


def test_too_many_roads_are_refused_before_parsing(tmp_path, capsys):
    path = tmp_path / "many.xodr"
    _many_roads(path, 20_001)
    start = time.perf_counter()
    assert main(["map", str(path)]) == 2
    assert time.perf_counter() - start < 5.0
    assert "roads_per_map" in capsys.readouterr().err


def test_too_large_a_file_is_refused_and_the_limit_can_be_raised(tmp_path, capsys):
    path = tmp_path / "some.xodr"
    _many_roads(path, 3)
    assert main(["map", str(path), "--max", "map_bytes=10"]) == 2
    assert "map_bytes" in capsys.readouterr().err
