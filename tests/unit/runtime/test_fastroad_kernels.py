"""`FastRoad`'s kernels: compiled, they give the bits of their Python (every callee
interpreted too), over random stations and offsets (off the ends, -0.0, NaN and inf) on a
road whose lanes come and go and a road with an elevation profile; they give the bits of
the code they replaced (the interpreted scalar calls and the numpy array calls, copied
below); and hand-checked poses and projections on a straight road."""

from __future__ import annotations

import bisect
import math
import types
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from addt_dsl.kernel import Kernel, bits
from addt_dsl.road import build_road, line, load_xodr
from addt_dsl.runtime import fastroad as F
from addt_dsl.runtime.agent_arrays import SCALE, S, T
from addt_dsl.runtime.fastroad import FastRoad
from addt_dsl.runtime.roadmesh import Elevation

DATA = Path(__file__).resolve().parents[2] / "data" / "xodr"


def _road(name: str) -> tuple[FastRoad, Elevation]:
    road = load_xodr(DATA / name).road("1")
    return FastRoad(road), Elevation(road)


ROADS = {"two_plus_one": _road("two_plus_one.xodr"), "curves_elevation": _road("curves_elevation.xodr")}


def interpreted(k: Kernel) -> types.FunctionType:
    """`k`'s Python with every kernel it calls interpreted as well."""
    fn = k.py_func
    callees = {name: interpreted(fn.__globals__[name]) for name in fn.__code__.co_names
               if isinstance(fn.__globals__.get(name), Kernel)}
    return types.FunctionType(fn.__code__, {**fn.__globals__, **callees}, fn.__name__, fn.__defaults__)


def _block(s, t) -> tuple[np.ndarray, np.ndarray]:
    """A block of agents (`AgentArrays.flat`) holding the stations and offsets, in its odd
    slots (the even ones padding)."""
    n = len(s)
    flat = np.zeros((5, 2 * n + 1))
    flat[SCALE] = 1.0
    cells = np.arange(1, 2 * n + 1, 2, dtype=np.intp)
    flat[S, cells], flat[T, cells] = s, t
    return flat, cells


def _pose_args(fast: FastRoad, elev: Elevation, flat, cells, rows, out):
    centres, starts, lanes = fast._lanes_tabled(-1)
    for k in range(len(starts)):
        centres, starts, lanes = fast._lanes_tabled(k)
    z, g = (elev._z_a, elev._g_a) if not elev.flat else (F._NO_PROFILE, F._NO_PROFILE)
    return (fast._tab, fast._ds, fast._last_i, fast.length, centres, starts, lanes, z, g, elev._ds, elev.length,
            flat, cells, rows, out)


def station(length: float):
    return (st.floats(-20.0, length + 20.0) | st.sampled_from([0.0, -0.0, length, length + 1e-9, 1e-300])
            | st.floats(0.0, length))


@settings(max_examples=40, deadline=None)
@given(st.sampled_from(sorted(ROADS)), st.data())
def test_pose_rows_compiled_gives_its_python_bits(name, data):
    fast, elev = ROADS[name]
    n = data.draw(st.integers(1, 12))
    s = data.draw(st.lists(station(fast.length), min_size=n, max_size=n))
    t = data.draw(st.lists(st.floats(-12.0, 12.0) | st.sampled_from([0.0, -0.0]), min_size=n, max_size=n))
    if data.draw(st.booleans()):  # a station or offset not finite: -2, the rows before it posed
        k = data.draw(st.integers(0, n - 1))
        (s if data.draw(st.booleans()) else t)[k] = data.draw(st.sampled_from([math.nan, math.inf, -math.inf]))
    flat, cells = _block(s, t)
    rows = np.array(data.draw(st.permutations(range(n))), dtype=np.intp)
    got, want = np.full((6, n), 7.0), np.full((6, n), 7.0)
    flat_got, flat_want = flat.copy(), flat.copy()
    r1 = F._pose_rows(*_pose_args(fast, elev, flat_got, cells, rows, got))
    with np.errstate(invalid="ignore"):
        r2 = interpreted(F._pose_rows)(*_pose_args(fast, elev, flat_want, cells, rows, want))
    assert r1 == r2 and (r1 == -2) == (not all(map(math.isfinite, s + t)))
    assert bits(got) == bits(want) and bits(flat_got) == bits(flat_want)


@settings(max_examples=40, deadline=None)
@given(st.sampled_from(sorted(ROADS)), st.data())
def test_ego_poses_give_the_scalar_calls_bits(name, data):
    """`FastRoad.ego_poses` over block rows in any order: each row's x, y, heading as given,
    `project` from its hint, `lane_offset` there and `elevation.at`, the scalar calls' bits
    (the twin posed each ego with them); False for a point or hint not finite."""
    fast, elev = ROADS[name]
    n = data.draw(st.integers(1, 8))
    points = np.zeros((n + 2, 4))
    hints = []
    for r in range(n):
        s = data.draw(st.floats(-5.0, fast.length + 5.0))
        x, y, h = fast.point(s, data.draw(st.floats(-9.0, 9.0)))
        points[r, :3] = x + data.draw(st.floats(-2.0, 2.0)), y, h
        hints.append(s + data.draw(st.floats(-3.0, 3.0)))
    rows = np.array(data.draw(st.permutations(range(n))), dtype=np.int64)
    hints_a = np.array([hints[r] for r in rows.tolist()])
    broken = data.draw(st.booleans())
    if broken:  # a coordinate or a hint not finite
        k = data.draw(st.integers(0, n - 1))
        bad = data.draw(st.sampled_from([math.nan, math.inf, -math.inf]))
        if data.draw(st.booleans()):
            hints_a[k] = bad
        else:
            points[rows[k], data.draw(st.integers(0, 1))] = bad
    out = np.full((n, 8), 7.0)
    assert fast.ego_poses(elev, points, rows, hints_a, out) is not broken
    if broken:
        return
    for j, r in enumerate(rows.tolist()):
        x, y, h = points[r, :3].tolist()
        s, t = fast.project(x, y, hints_a[j].item())
        want = [x, y, h, s, t, fast.lane_offset(s, t), *elev.at(s)]
        assert bits(out[j].tolist()) == bits(want)


@settings(max_examples=60, deadline=None)
@given(st.sampled_from(sorted(ROADS)), st.data())
def test_project_compiled_gives_its_python_bits(name, data):
    fast, _ = ROADS[name]
    s = data.draw(station(fast.length))
    t = data.draw(st.floats(-30.0, 30.0))
    x, y, _ = fast.point(s, t)
    x += data.draw(st.floats(-5.0, 5.0))
    hinted = data.draw(st.booleans())
    hint = data.draw(station(fast.length)) if hinted else 0.0
    if data.draw(st.integers(0, 9)) == 0:
        x = math.nan
    args = (fast._tab, fast._ds, fast._last_i, fast.length, x, y, hint, hinted)
    if math.isnan(x):  # a NaN station after the first step: int() of it raised, and raises
        for project in (F._project, interpreted(F._project)):
            with pytest.raises(ValueError):
                project(*args)
        return
    assert bits(F._project(*args)) == bits(interpreted(F._project)(*args))


# ---- the code the kernels replaced, as it was (agents posed by these, bit for bit)

def old_index(f, s):
    i = int(s / f._ds)
    i = 0 if i < 0 else min(i, f._last_i)
    return i, (s - f._s[i]) / f._ds


def old_reference_pose(f, s):
    i, u = old_index(f, s)
    xs, ys, hs = f._x, f._y, f._h
    x, y, h = xs[i] + u * (xs[i + 1] - xs[i]), ys[i] + u * (ys[i + 1] - ys[i]), hs[i] + u * (hs[i + 1] - hs[i])
    if s > f.length:
        extra = s - f.length
        h = f._h[-1]
        x, y = f._x[-1] + extra * math.cos(h), f._y[-1] + extra * math.sin(h)
    elif s < 0.0:
        x, y, h = f._x[0] + s * math.cos(f._h[0]), f._y[0] + s * math.sin(f._h[0]), f._h[0]
    return x, y, h


def old_point(f, s, t):
    x, y, h = old_reference_pose(f, s)
    return x - math.sin(h) * t, y + math.cos(h) * t, h


def old_ground_scale(f, s, t):
    if s > f.length or s < 0.0:
        return 1.0
    i, u = old_index(f, s)
    g = 1.0 - (f._k[i] + u * (f._k[i + 1] - f._k[i])) * t
    return g if g > F.MIN_GROUND_SCALE else F.MIN_GROUND_SCALE


def old_lane_offset(f, s, t):
    i, u = old_index(f, s)
    best_d, best_c = math.inf, None
    for lane in f.road.driving_lane_ids(min(max(f.road.sections[max(0, bisect.bisect_right(
            [sec.s0 for sec in f.road.sections], s) - 1)].s0 + 1e-6, 0.0), f.length)):
        f.lane_center_t(lane, s)
        table = f._center_cache[lane]
        c = table[i] + u * (table[i + 1] - table[i])
        if abs(t - c) < best_d:
            best_d, best_c = abs(t - c), c
    return t if best_c is None else t - best_c


def old_project(f, x, y, hint=None):
    if hint is None:
        d = f._xy - (x, y)
        s = f._s[int(np.argmin(np.einsum("ij,ij->i", d, d)))]
    else:
        s = hint
    for _ in range(3):
        rx, ry, h = old_reference_pose(f, s)
        ds = (x - rx) * math.cos(h) + (y - ry) * math.sin(h)
        s = min(max(s + ds, 0.0), f.length)
        if abs(ds) < 1e-6:
            break
    rx, ry, h = old_reference_pose(f, s)
    return s, -(x - rx) * math.sin(h) + (y - ry) * math.cos(h)


def old_elevation(e, s):
    if e.flat:
        return 0.0, 0.0
    z, g = e._z_a.tolist(), e._g_a.tolist()
    u = min(max(s, 0.0), e.length) / e._ds
    i = min(int(u), len(z) - 2)
    f = u - i
    return z[i] + f * (z[i + 1] - z[i]), g[i] + f * (g[i + 1] - g[i])


def old_points(f, s, t):
    """The numpy array call (`FastRoad.points`) as it was."""
    i = np.minimum(np.maximum(s / f._ds, 0.0), f._last_i).astype(np.intp)
    u = (s - np.array(f._s)[i]) / f._ds
    table = np.array([f._x, f._y, f._h])
    lo = table[:, i]
    x, y, h = lo + u * (table[:, i + 1] - lo)
    for j in np.flatnonzero((s > f.length) | (s < 0.0)).tolist():
        x[j], y[j], h[j] = old_reference_pose(f, float(s[j]))
    hl = h.tolist()
    return (x - np.fromiter(map(math.sin, hl), float, len(hl)) * t,
            y + np.fromiter(map(math.cos, hl), float, len(hl)) * t, h)


@pytest.mark.parametrize("name", sorted(ROADS))
def test_kernels_give_the_replaced_codes_bits(name):
    fast, elev = ROADS[name]
    rng = np.random.default_rng(7)
    s = np.concatenate([rng.uniform(-10.0, fast.length + 10.0, 300), [0.0, -0.0, fast.length, 1e-300],
                        [sec.s0 for sec in fast.road.sections]])
    t = np.concatenate([rng.uniform(-9.0, 9.0, 300), [0.0, -0.0, 1.75, -5.25]])
    t = np.resize(t, len(s))
    sl, tl = s.tolist(), t.tolist()
    for si, ti in zip(sl, tl):
        assert bits(fast.reference_pose(si)) == bits(old_reference_pose(fast, si))
        assert bits(fast.point(si, ti)) == bits(old_point(fast, si, ti))
        assert bits([fast.ground_scale(si, ti)]) == bits([old_ground_scale(fast, si, ti)])
        assert bits([fast.lane_offset(si, ti)]) == bits([old_lane_offset(fast, si, ti)])
        assert bits(elev.at(si)) == bits(old_elevation(elev, si))
        x, y, _ = fast.point(si, ti)
        assert bits(fast.project(x + 0.4, y - 0.3, si + 0.7)) == bits(old_project(fast, x + 0.4, y - 0.3, si + 0.7))
    for si, ti in zip(sl[:20], tl[:20]):
        x, y, _ = fast.point(si, ti)
        assert bits(fast.project(x, y)) == bits(old_project(fast, x, y))
    flat, cells = _block(s, t)
    out = np.empty((6, len(s)))
    assert fast.pose_rows(elev, flat, cells, np.arange(len(s), dtype=np.intp), out)
    x, y, h = old_points(fast, s, t)
    assert bits(out[[F.POSE_X, F.POSE_Y, F.POSE_H]]) == bits([x, y, h])
    assert bits(out[F.POSE_OFFSET]) == bits([old_lane_offset(fast, si, ti) for si, ti in zip(sl, tl)])
    assert bits(flat[SCALE, cells]) == bits([old_ground_scale(fast, si, ti) for si, ti in zip(sl, tl)])
    assert bits(out[[F.POSE_Z, F.POSE_GRADE]].T) == bits([old_elevation(elev, si) for si in sl])


def test_sections_are_tabled_when_first_asked():
    """A section's lanes enter the kernel's tables the first time an actor is there (their
    centres sampled then, as `lane_center_t` samples them)."""
    road = load_xodr(DATA / "two_plus_one.xodr").road("1")
    fast = FastRoad(road)
    s0 = [sec.s0 for sec in road.sections]
    assert fast.lane_offset(s0[1] + 1.0, -1.0) == old_lane_offset(FastRoad(road), s0[1] + 1.0, -1.0)
    _, _, lanes = fast._lane_tables
    assert lanes[1, 0] == len(fast.driving_lane_ids(s0[1] + 1.0)) and (lanes[[0, 2, 3, 4], 0] == -1).all()
    flat, cells = _block([s0[3] + 2.0, s0[0] + 2.0], [-1.0, 2.0])
    out = np.empty((6, 2))
    assert fast.pose_rows(Elevation(road), flat, cells, np.arange(2, dtype=np.intp), out)
    assert (fast._lane_tables[2][[0, 1, 3], 0] >= 0).all() and fast._lane_tables[2][2, 0] == -1
    want = [old_lane_offset(fast, s0[3] + 2.0, -1.0), old_lane_offset(fast, s0[0] + 2.0, 2.0)]
    assert out[F.POSE_OFFSET].tolist() == want


def test_straight_road_by_hand():
    """A straight road along x: the point at (s, t) is (s, t) heading 0, past the end
    straight on; ground scale 1; the lane offset from the nearest lane centre (lanes 3.5 m
    wide: right lanes' centres at -1.75 and -5.25); a point projects onto its (s, t)."""
    fast = FastRoad(build_road("r", [line(200.0)], 0, 2, 3.5).road("r"))
    assert fast.point(50.0, -1.75) == (50.0, -1.75, 0.0)
    assert fast.point(210.0, 1.0) == (210.0, 1.0, 0.0)
    assert fast.point(-5.0, 0.0) == (-5.0, 0.0, 0.0)
    assert fast.ground_scale(80.0, -3.0) == 1.0
    assert fast.lane_offset(80.0, -2.0) == pytest.approx(-0.25)
    assert fast.lane_offset(80.0, -4.0) == pytest.approx(1.25)
    assert fast.project(120.25, -4.5, 100.0) == pytest.approx((120.25, -4.5))
    assert fast.project(120.25, -4.5) == pytest.approx((120.25, -4.5))
    for s, error in ((math.nan, ValueError), (math.inf, OverflowError)):  # as int() of them, interpreted
        with pytest.raises(error, match="cannot convert float"):
            fast.reference_pose(s)
        with pytest.raises(error, match="cannot convert float"):
            old_reference_pose(fast, s)
