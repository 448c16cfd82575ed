"""`addtc map FILE.xodr`: the ids a user needs to write routes, as text and as a picture."""

from __future__ import annotations

from pathlib import Path

from addt_dsl.cli import main

MAPS = Path(__file__).resolve().parents[3] / "examples" / "maps"


def test_map_lists_roads_lanes_junctions(capsys):
    assert main(["map", str(MAPS / "fabriksgatan.xodr")]) == 0
    out = capsys.readouterr().out
    assert "fabriksgatan.xodr: 16 roads, 1 junction, 0 signals" in out
    # Lanes with their driving direction (right-hand traffic: positive ids against s).
    assert "road 0: 93.7 m, RHT; start: junction 4; end: -" in out
    assert "1 driving -s, -1 driving +s" in out
    # Each connection with its turn, the road it leads to and its lane links.
    assert "2: road 0 -> 10 left -> road 3 (lanes 1->-1)" in out
    assert "0: road 0 -> 8 right -> road 1 (lanes 1->-1, 2->-2, 3->-3)" in out


def test_map_direct_junction_and_png(tmp_path, capsys):
    png = tmp_path / "map.png"
    assert main(["map", str(MAPS / "soderleden.xodr"), "--png", str(png)]) == 0
    out = capsys.readouterr().out
    assert "1: road 5 -> road 0 (direct; lanes -1->-3, -2->-4, -3->-5)" in out
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000


def test_map_lists_signals(tmp_path, capsys):
    xodr = (MAPS / "fabriksgatan.xodr").read_text()
    road3 = xodr.index('id="3" junction="-1"')
    signal = '<signal s="109.0" t="-4.0" id="7" name="north" dynamic="yes" orientation="+"/>'
    at = xodr.index("<signals>", road3) + len("<signals>")  # road 3's (empty) signals element
    (tmp_path / "lights.xodr").write_text(xodr[:at] + signal + xodr[at:])
    assert main(["map", str(tmp_path / "lights.xodr")]) == 0
    assert "7 'north': road 3 s 109.0 m t -4.0 m, traffic light, type -/-, facing +" in capsys.readouterr().out


def test_map_of_a_bad_file_is_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.xodr"
    bad.write_text("<OpenDRIVE><road id='1' length='-3'/></OpenDRIVE>")
    assert main(["map", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: cannot read") and "Traceback" not in err


def test_map_lists_signal_validity_and_controllers():
    from addt_dsl.reporting.roadmap import describe
    from addt_dsl.runtime.road import parse_xodr

    path = Path(__file__).resolve().parents[3] / "examples" / "maps" / "fabriksgatan_traffic_lights.xodr"
    text = path.read_text().replace("</OpenDRIVE>", '<controller id="5" name="west"><control signalId="1"/>'
                                    '<control signalId="2"/></controller></OpenDRIVE>')
    out = describe(parse_xodr(text))
    assert "facing +, lanes -1..1" in out
    assert "controllers:\n  5 'west': signals 1, 2" in out
