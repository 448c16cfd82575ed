"""Reading the sample maps, lane layout, and the safety/error behaviour of the reader."""

import math
from pathlib import Path

import numpy as np
import pytest

from addt_dsl.road import XodrError, load_xodr, parse_xodr
from addt_dsl.road.geometry import end_pose

DATA = Path(__file__).resolve().parents[2] / "data" / "xodr"
SAMPLE_MAPS = sorted(DATA.glob("*.xodr"))

# Worst gap between consecutive geometries as written in each file [m]. The files store
# start points rounded by their authoring tool; curves_elevation's spiral joints are only
# good to ~1.2e-5 m (pyclothoids gives the same end points as we do to 1e-13 m).
CONTINUITY_TOL_M = {"curves_elevation.xodr": 2e-5}


def test_all_six_sample_maps_present():
    assert {p.name for p in SAMPLE_MAPS} == {
        "straight_500m.xodr", "curve_r100.xodr", "curves_elevation.xodr",
        "jolengatan.xodr", "lane_width_and_offset.xodr", "two_plus_one.xodr",
    }


@pytest.mark.parametrize("path", SAMPLE_MAPS, ids=lambda p: p.name)
def test_sample_map_loads(path):
    net = load_xodr(path)
    assert net.roads and net.source_name == str(path)
    for road in net.roads.values():
        end = road.geometries[-1].s0 + road.geometries[-1].length
        assert end == pytest.approx(road.length, abs=1e-9)
        x, y, h = road.reference_pose(np.linspace(0.0, road.length, 50))
        assert np.all(np.isfinite(x) & np.isfinite(y) & np.isfinite(h))


@pytest.mark.parametrize("path", SAMPLE_MAPS, ids=lambda p: p.name)
def test_planview_is_continuous(path):
    tol = CONTINUITY_TOL_M.get(path.name, 1e-6)
    for road in load_xodr(path).roads.values():
        gs = road.geometries
        for g0, g1 in zip(gs, gs[1:]):
            x, y, h = end_pose(g0)
            x1, y1, h1 = g1.pose(g1.s0)
            assert g0.s0 + g0.length == pytest.approx(g1.s0, abs=1e-9)
            assert math.hypot(x - x1, y - y1) < tol, (road.id, g0.s0)
            assert abs(math.remainder(h - h1, 2 * math.pi)) < 1e-9, (road.id, g0.s0)


def test_curve_r100_closed_form():
    road = load_xodr(DATA / "curve_r100.xodr").road("0")
    assert road.curvature(600.0) == pytest.approx(0.01)
    # Middle of the quarter circle around centre (500, 100) with R = 100 m.
    x, y, h = road.reference_pose(500.0 + 25.0 * math.pi)
    assert (x, y) == pytest.approx((500.0 + 100 * math.sin(math.pi / 4), 100 - 100 * math.cos(math.pi / 4)), abs=1e-6)
    assert h == pytest.approx(math.pi / 4, abs=1e-12)
    assert road.reference_pose(road.length) == pytest.approx((600.0, 200.0, math.pi / 2), abs=1e-6)
    assert road.driving_lane_ids(10.0) == (1, -1)
    assert road.lane_ids(10.0) == (2, 1, -1, -2)
    assert road.lane_type(2, 10.0) == "border"


def test_elevation_profile():
    road = load_xodr(DATA / "curves_elevation.xodr").road("1")
    assert road.elevation(0.0) == 0.0
    s = 100.0
    ds = s - 72.149967203525861
    expected = (-1.4207722866392594 - 3.5625342062508572e-02 * ds - 1.6874417257835937e-04 * ds**2
                + 3.2567351175048125e-06 * ds**3)
    assert road.elevation(s) == pytest.approx(expected, abs=1e-12)
    z = road.elevation(np.linspace(0.0, road.length, 1000))
    assert np.max(np.abs(np.diff(z))) < 0.2  # the 16 records join up smoothly


def test_lane_width_and_offset_map():
    net = load_xodr(DATA / "lane_width_and_offset.xodr")
    road = net.road("4")
    for s in (0.0, 2.5, 7.0, 10.0):
        assert net.lane_width("4", -1, s) == pytest.approx(s, abs=1e-12)  # width = s
        assert road.lane_offset_at(s) == pytest.approx(s, abs=1e-12)  # laneOffset = s
        # Lane -1 spans t in [offset - width, offset] = [0, s]; centre at s/2.
        assert road.lane_center_t(-1, s) == pytest.approx(s / 2, abs=1e-12)
        x, y, h = net.lane_center("4", -1, s)
        assert x == pytest.approx(10.0 + s * math.cos(1.0) - math.sin(1.0) * s / 2, abs=1e-12)
        assert y == pytest.approx(-10.0 + s * math.sin(1.0) + math.cos(1.0) * s / 2, abs=1e-12)
        # The centre line drifts left at dt/ds = 1/2, so its tangent turns by atan(1/2);
        # at s = 10 the constant records (b = 0) take over.
        assert h == pytest.approx(1.0 + (math.atan(0.5) if s < 10.0 else 0.0), abs=1e-12)
    assert road.lane_ids(0.0) == ()  # zero width at the start
    assert road.lane_ids(5.0) == (-1,)


def test_two_plus_one_lane_layout():
    net = load_xodr(DATA / "two_plus_one.xodr")
    road = net.road("1")
    assert [sec.s0 for sec in road.sections] == [0.0, 125.0, 175.0, 325.0, 375.0]
    assert road.lane_ids(0.0) == (2, 1, -1)
    assert road.lane_ids(125.0) == (2, 1, -2)  # lane -1 starts with zero width
    assert road.lane_ids(150.0) == (2, 1, -1, -2)
    assert road.lane_ids(200.0) == (1, -1, -2)
    assert road.lane_ids(400.0) == (2, 1, -1)
    # Mid-transition: laneOffset = 0.0042 ds² - 5.6e-5 ds³ = 1.75 m at ds = 25 m.
    assert road.lane_offset_at(150.0) == pytest.approx(1.75, abs=1e-12)
    assert net.lane_width("1", 1, 150.0) == pytest.approx(1.75, abs=1e-12)
    assert net.lane_width("1", -1, 150.0) == pytest.approx(1.75, abs=1e-12)
    assert net.lane_center("1", -1, 150.0)[:2] == pytest.approx((150.0, 0.875), abs=1e-12)
    # The outer road edges never move: t in [-3.5, 7.0] everywhere.
    lo, hi = road.road_band_t(np.linspace(0.0, 500.0, 2001))
    np.testing.assert_allclose(lo, -3.5, atol=1e-9)
    np.testing.assert_allclose(hi, 7.0, atol=1e-9)
    with pytest.raises(ValueError, match="no lane -2"):
        net.lane_center("1", -2, 50.0)
    with pytest.raises(ValueError, match="outside"):
        net.reference_pose("1", 500.1)


# ------------------------------------------------------------------ safety / errors

BILLION_LAUGHS = """<?xml version="1.0"?>
<!DOCTYPE lolz [
 <!ENTITY lol "lol">
 <!ENTITY lol2 "&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;">
 <!ENTITY lol3 "&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;">
 <!ENTITY lol4 "&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;">
 <!ENTITY lol9 "&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;">
]>
<OpenDRIVE><header name="&lol9;"/></OpenDRIVE>
"""

EXTERNAL_ENTITY = """<?xml version="1.0"?>
<!DOCTYPE OpenDRIVE [ <!ENTITY xxe SYSTEM "file:///etc/passwd"> ]>
<OpenDRIVE><header name="&xxe;"/></OpenDRIVE>
"""

EXTERNAL_DTD = """<?xml version="1.0"?>
<!DOCTYPE OpenDRIVE SYSTEM "http://example.invalid/evil.dtd">
<OpenDRIVE><header/></OpenDRIVE>
"""


def test_billion_laughs_is_refused(tmp_path):
    f = tmp_path / "laughs.xodr"
    f.write_text(BILLION_LAUGHS)
    with pytest.raises(XodrError, match="unsafe XML") as info:
        load_xodr(f)
    assert info.value.element == "!ENTITY" and info.value.line is not None


@pytest.mark.parametrize("text", [EXTERNAL_ENTITY, EXTERNAL_DTD], ids=["entity", "dtd"])
def test_external_references_are_refused(text):
    with pytest.raises(XodrError, match="unsafe XML"):
        parse_xodr(text)


MINIMAL = """<?xml version="1.0" encoding="UTF-8"?>
<OpenDRIVE>
  <header revMajor="1" revMinor="6"/>
  <road id="7" length="10" junction="-1">
    <planView>
      <geometry s="0" x="0" y="0" hdg="0" length="10">
        {geometry}
      </geometry>
    </planView>
    <lanes>
      <laneSection s="0">
        <center><lane id="0" type="none"/></center>
        <right>{lane}</right>
      </laneSection>
    </lanes>
    {extra}
  </road>
  {top}
</OpenDRIVE>
"""
LANE = '<lane id="-1" type="driving"><width sOffset="0" a="3" b="0" c="0" d="0"/></lane>'


def _doc(geometry="<line/>", lane=LANE, extra="", top=""):
    return MINIMAL.format(geometry=geometry, lane=lane, extra=extra, top=top)


def test_minimal_document_and_ignored_elements():
    extra = """<objects><object id="1" s="1" t="1"/></objects><signals><signal id="s"/></signals>
    <userData code="x"><anything/></userData><surface/><railroad/>"""
    top = '<controller id="1"/><station id="2"/><userData/>'
    net = parse_xodr(_doc(extra=extra, top=top), source_name="min.xodr")
    assert net.road(7).lane_ids(5.0) == (-1,)
    assert net.road("7").reference_pose(10.0) == pytest.approx((10.0, 0.0, 0.0))


def test_bytes_and_namespaced_input():
    text = _doc().replace("<OpenDRIVE>", '<OpenDRIVE xmlns="http://www.asam.net/xml/opendrive">')
    assert parse_xodr(text.encode("utf-8")).road("7").length == 10.0


@pytest.mark.parametrize(
    "kwargs,element,line,message",
    [
        ({"geometry": "<clothoidSpline/>"}, "clothoidSpline", 7, "unsupported planView geometry"),
        ({"geometry": '<arc curvature="abc"/>'}, "arc", 7, "not a number"),
        ({"geometry": "<arc/>"}, "arc", 7, "missing attribute 'curvature'"),
        ({"geometry": '<paramPoly3 pRange="bogus" aU="0" bU="1" cU="0" dU="0" aV="0" bV="0" cV="0" dV="0"/>'},
         "paramPoly3", 7, "pRange"),
        ({"geometry": "<line/><arc curvature='0.1'/>"}, "geometry", 6, "exactly one"),
        ({"lane": '<lane id="-1" type="driving"><border sOffset="0" a="3" b="0" c="0" d="0"/></lane>'},
         "lane", 13, "border"),
        ({"lane": '<lane id="-2" type="driving"><width sOffset="0" a="3" b="0" c="0" d="0"/></lane>'},
         "laneSection", 11, "lane ids"),
        ({"lane": '<lane id="1" type="driving"><width sOffset="0" a="3" b="0" c="0" d="0"/></lane>'},
         "lane", 13, "does not belong"),
        ({"lane": '<lane id="-1" type="driving"/>'}, "lane", 13, "missing <width>"),
        ({"extra": '<link><successor elementType="road" elementId="9" contactPoint="middle"/></link>'},
         "successor", 16, "contactPoint"),
    ],
)
def test_errors_carry_element_and_line(kwargs, element, line, message):
    with pytest.raises(XodrError, match=message) as info:
        parse_xodr(_doc(**kwargs), source_name="bad.xodr")
    err = info.value
    assert (err.element, err.line) == (element, line)
    assert str(err).startswith(f"bad.xodr:{line}: <{element}>")


def test_malformed_xml_and_wrong_root():
    with pytest.raises(XodrError, match="malformed XML") as info:
        parse_xodr("<OpenDRIVE>\n<road>\n</OpenDRIVE>")
    assert info.value.line == 3
    with pytest.raises(XodrError, match="root element") as info:
        parse_xodr("<Scenario/>")
    assert info.value.element == "Scenario" and info.value.line == 1


def test_an_unknown_declared_encoding_is_an_xodr_error():
    with pytest.raises(XodrError, match="cannot decode the file: unknown encoding: abc"):
        parse_xodr(b'<?xml version="1.0" encoding="abc"?><OpenDRIVE/>')


def test_road_without_planview_or_lanes():
    with pytest.raises(XodrError, match="planView"):
        parse_xodr('<OpenDRIVE><road id="1" length="5"><lanes/></road></OpenDRIVE>')
    with pytest.raises(XodrError, match="missing attribute 'length'"):
        parse_xodr('<OpenDRIVE><road id="1"/></OpenDRIVE>')
    with pytest.raises(XodrError, match="duplicate road id"):
        parse_xodr(_doc().replace("</OpenDRIVE>", _doc().split("<OpenDRIVE>")[1]))
