"""Road meshes: the surface covers the lanes at the road's height; markings sit on the
lane borders, solid at edges and between directions, dashed between same-direction lanes."""

from pathlib import Path

import numpy as np
import pytest

from addt_dsl.runtime import roadmesh as RM
from addt_dsl.road import arc, build_road, line, load_xodr

XODR = Path(__file__).resolve().parents[2] / "data" / "xodr"


@pytest.fixture(scope="module")
def two_lane():
    return build_road("r", [line(150.0), arc(120.0, 0.01), line(80.0)], left_lanes=0, right_lanes=2,
                      lane_width_m=3.5).road("r")


@pytest.fixture(scope="module")
def hills():
    net = load_xodr(XODR / "curves_elevation.xodr")
    return net.road(next(iter(net.roads)))


def _road_coords(road, pts):
    s, t, _ = road.project_array(pts[:, 0], pts[:, 1])
    return s, t


def test_surface_area_is_length_times_width(two_lane):
    meshes = RM.surface_meshes(two_lane)
    area = sum(m.area() for m in meshes)
    # Lanes right of the reference line lie outside the left-turning arc (120 m at
    # 0.01 /m): the band area is 7 m * length + kappa * (7 m)^2 / 2 * arc length.
    # The strip is built from chords: agreement to 0.05 %.
    assert area == pytest.approx(two_lane.length * 7.0 + 0.01 * 24.5 * 120.0, rel=5e-4)
    assert {m.name.split("/")[-1] for m in meshes} == {"asphalt"}


def test_surface_triangles_face_up_and_chunks_are_short(two_lane):
    for m in RM.surface_meshes(two_lane):
        tri = m.vertices[m.indices.reshape(-1, 3)]
        normal_z = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])[:, 2]
        assert np.all(normal_z > 0.0)
        s, _ = _road_coords(two_lane, m.vertices)
        assert s.max() - s.min() <= RM.CHUNK_M + 1e-6
        assert m.indices.max() < len(m.vertices)


def test_surface_vertices_follow_elevation_and_lane_borders(hills):
    meshes = RM.surface_meshes(hills)
    assert meshes
    for m in meshes[:12]:
        s, t = _road_coords(hills, m.vertices)
        assert np.abs(m.vertices[:, 2] - hills.elevation(s)).max() < 1e-6
        lo, hi = hills.road_band_t(s)
        assert np.all((t >= lo - 1e-6) & (t <= hi + 1e-6))
    # Border lanes are drawn in the shoulder colour, the lanes in asphalt.
    kinds = {m.name.split("/")[-1] for m in meshes}
    assert "asphalt" in kinds and len(kinds) >= 2


def test_surface_follows_the_curve_closely(two_lane):
    # Every vertex lies on a lane border within 5 mm (chord error on the r = 100 m arc).
    borders = np.array([0.0, -3.5, -7.0])
    for m in RM.surface_meshes(two_lane):
        _, t = _road_coords(two_lane, m.vertices)
        assert np.abs(t[:, None] - borders[None, :]).min(axis=1).max() < 5e-3


def test_markings_solid_at_the_edges_dashed_between_lanes(two_lane):
    lines = RM.marking_lines(two_lane, two_lane.sections[0])
    # Columns left to right: t = 0 (left edge), -3.5 (between lanes -1/-2), -7 (right edge).
    assert [(ln.border, ln.dashed) for ln in lines] == [(0, False), (1, True), (2, False)]
    meshes = RM.marking_meshes(two_lane)
    pts = np.concatenate([m.vertices for m in meshes])
    s, t = _road_coords(two_lane, pts)
    assert np.all(pts[:, 2] == pytest.approx(RM.MARK_LIFT_M))
    near = {b: np.abs(t - b) < RM.MARK_WIDTH_M for b in (0.0, -3.5, -7.0)}
    assert sum(near.values()).astype(bool).all()  # every marking vertex sits on a border
    # Solid lines cover the whole length; dashes DASH_M of every DASH_M + GAP_M.
    painted = {0.0: 0.0, -3.5: 0.0, -7.0: 0.0}
    for m in meshes:
        tri = m.vertices[m.indices.reshape(-1, 3)]
        _, t_c = _road_coords(two_lane, tri.mean(axis=1))
        area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
        for b in painted:
            painted[b] += area[np.abs(t_c - b) < RM.MARK_WIDTH_M].sum() / RM.MARK_WIDTH_M
    assert painted[0.0] == pytest.approx(two_lane.length, rel=0.02)
    assert painted[-7.0] == pytest.approx(two_lane.length + 0.01 * 7.0 * 120.0, rel=0.02)
    assert painted[-3.5] == pytest.approx(two_lane.length * RM.DASH_M / (RM.DASH_M + RM.GAP_M), rel=0.05)


def test_centre_line_between_opposite_directions_is_solid():
    road = build_road("r", [line(100.0)], left_lanes=1, right_lanes=1, lane_width_m=3.5).road("r")
    lines = RM.marking_lines(road, road.sections[0])
    assert [(ln.border, ln.dashed) for ln in lines] == [(0, False), (1, False), (2, False)]


def test_elevation_table_matches_the_road(hills):
    elev = RM.Elevation(hills)
    assert not elev.flat
    s = np.linspace(0.0, hills.length, 401)
    z = np.array([elev.at(v)[0] for v in s])
    grade = np.array([elev.at(v)[1] for v in s])
    assert np.abs(z - hills.elevation(s)).max() < 1e-3
    assert np.abs(grade - hills.elevation_profile.derivative(s)).max() < 2e-3
    assert RM.Elevation(build_road("f", [line(50.0)], 0, 1, 3.5).road("f")).flat


def test_stations_densify_in_curves_and_crests(two_lane):
    straight = RM.surface_stations(two_lane, 0.0, 100.0)
    curve = RM.surface_stations(two_lane, 160.0, 260.0)
    assert np.diff(straight).max() <= RM.MAX_STEP_M + 1e-9
    assert np.diff(curve).max() <= RM.MAX_TURN_RAD / 0.01 + 0.5
    assert len(curve) > len(straight)
