"""Agreement with an independent evaluator: the ASAM OpenDRIVE quality checker.

``asam-qc-opendrive`` (dev/test-only dependency) evaluates the reference line
(``get_point_xyz_from_road_reference_line``, pyclothoids for spirals) and lane centres
(``get_middle_point_xyz_at_height_zero_from_lane_by_s``) by s. We sample every road of
every sample map every 1 m (plus the road end) and require agreement to 1e-6 m.
"""

import math
from pathlib import Path

import numpy as np
import pytest

from addt_dsl.road import load_xodr

SAMPLE_MAPS = sorted((Path(__file__).resolve().parents[2] / "data" / "xodr").glob("*.xodr"))

qc = pytest.importorskip("qc_opendrive.base.utils", reason="needs the ASAM OpenDRIVE checker: "
                         "pip install --no-deps -r tests/requirements-opendrive-checker.txt")

TOL_M = 1e-6


def _samples(length):
    return np.unique(np.append(np.arange(0.0, length, 1.0), length))


def _qc_lanes(road):
    """(lane section element, lane element, lane id) per lane, by section."""
    out = []
    for section in qc.get_lane_sections(road):
        for lane in qc.get_left_lanes_from_lane_section(section) + qc.get_right_lanes_from_lane_section(section):
            out.append((section, lane, qc.get_lane_id(lane)))
    return out


@pytest.mark.parametrize("path", SAMPLE_MAPS, ids=lambda p: p.name)
def test_reference_line_and_lane_centres_agree_with_asam_qc(path):
    net = load_xodr(path)
    root = qc.get_root_without_default_namespace(str(path))
    worst = 0.0
    checked = 0
    for road_el in qc.get_roads(root):
        road = net.road(road_el.get("id"))
        s_all = _samples(road.length)
        x, y, h = road.reference_pose(s_all)
        z = road.elevation(s_all)
        for i, s in enumerate(s_all):
            p = qc.get_point_xyz_from_road_reference_line(road_el, float(s))
            hq = qc.get_heading_from_road_reference_line(road_el, float(s))
            worst = max(worst, abs(p.x - x[i]), abs(p.y - y[i]), abs(p.z - z[i]))
            assert abs(math.remainder(hq - h[i], 2 * math.pi)) < 1e-9, (road.id, s)
            checked += 1
        sec_starts = [float(sec.get("s")) for sec in qc.get_lane_sections(road_el)]
        for section_el, lane_el, lane_id in _qc_lanes(road_el):
            s0 = float(section_el.get("s"))
            later = [b for b in sec_starts if b > s0]
            s1 = min(later) if later else road.length
            # qc picks the section by s itself; sample only inside this section.
            s_sec = s_all[(s_all >= s0) & ((s_all < s1) | (s1 == road.length))]
            if s_sec.size == 0:
                continue
            xc, yc, _ = road.lane_center(lane_id, s_sec)
            for j, s in enumerate(s_sec):
                ls = qc.get_lane_section_from_road_by_s(road_el, float(s))
                assert float(ls.get("s")) == s0
                p = qc.get_middle_point_xyz_at_height_zero_from_lane_by_s(road_el, ls, lane_el, float(s))
                worst = max(worst, abs(p.x - xc[j]), abs(p.y - yc[j]))
                checked += 1
    assert checked > 0
    print(f"{path.name}: {checked} points, max deviation {worst:.3e} m")
    assert worst < TOL_M
