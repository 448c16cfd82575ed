"""`addtc map FILE.xodr`: the ids a user needs to write routes, as text and as a picture."""

from __future__ import annotations

import re
from pathlib import Path

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

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
    from addt_dsl.road import parse_xodr

    path = Path(__file__).resolve().parents[3] / "examples" / "maps" / "fabriksgatan_traffic_lights.xodr"
    text = path.read_text().replace("</OpenDRIVE>", '<controller id="5" name="west"><control signalId="1"/>'
                                    '<control signalId="2"/></controller></OpenDRIVE>')
    out = describe(parse_xodr(text))
    assert "facing +, lanes -1..1" in out
    assert "controllers:\n  5 'west': signals 1, 2" in out


def test_a_map_that_declares_an_unknown_encoding_is_one_line(tmp_path, capsys):
    """`<?xml ... encoding="abc"?>` was 'internal error: LookupError: unknown encoding' (exit 3)."""
    bad = tmp_path / "enc.xodr"
    text = (MAPS / "straight_500m.xodr").read_text()
    bad.write_text(text.replace('<?xml version="1.0"', '<?xml version="1.0" encoding="abc"', 1))
    assert main(["map", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err == f"error: cannot read {bad}: {bad}:1: cannot decode the file: unknown encoding: abc\n", err


VALUES = ["", "-1", "1e308", "nan", "inf", "0", "-5", "999999", "1.5", "abc", "1e-300", "3", "utf-16", "abc"]
TEXTS = [p.read_text() for p in sorted(MAPS.glob("*.xodr"))]


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_any_attribute_value_is_a_map_or_one_line(tmp_path, capsys, data):
    """Fuzz: attribute values of the example maps (the XML declaration's included) replaced by
    hostile ones: `addtc map` prints the map (0) or one line (2), never an internal error."""
    text = data.draw(st.sampled_from(TEXTS))
    for _ in range(data.draw(st.integers(1, 4))):
        spans = [m.span(2) for m in re.finditer(r'(\w+)="([^"]*)"', text)]
        a, b = data.draw(st.sampled_from(spans))
        text = text[:a] + data.draw(st.sampled_from(VALUES)) + text[b:]
    path = tmp_path / "fuzz.xodr"
    path.write_text(text)
    capsys.readouterr()
    code = main(["map", str(path)])
    err = capsys.readouterr().err
    assert code in (0, 2) and "internal error" not in err and "Traceback" not in err, err
