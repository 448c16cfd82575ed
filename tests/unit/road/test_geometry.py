"""Per-primitive checks against closed forms and independent numeric integration."""

import math

import numpy as np
import pytest

from addt_dsl.road.geometry import (
    Arc,
    CubicProfile,
    Line,
    ParamPoly3,
    Poly3,
    Spiral,
    end_pose,
    param_poly3,
    place,
    spiral,
)


def _integrate_heading(heading_fn, s_end, n=200001):
    """Independent reference: x, y = ∫ (cos, sin)(θ(u)) du by composite Simpson."""
    u = np.linspace(0.0, s_end, n)
    th = heading_fn(u)
    w = np.ones(n)
    w[1:-1:2], w[2:-1:2] = 4.0, 2.0
    h = s_end / (n - 1)
    return h / 3.0 * np.sum(w * np.cos(th)), h / 3.0 * np.sum(w * np.sin(th))


def test_line_closed_form():
    g = Line(10.0, 1.0, 2.0, 0.3, 50.0)
    x, y, h = g.pose(35.0)
    assert x == pytest.approx(1.0 + 25.0 * math.cos(0.3), abs=1e-12)
    assert y == pytest.approx(2.0 + 25.0 * math.sin(0.3), abs=1e-12)
    assert h == 0.3 and g.curvature(35.0) == 0.0
    xs, ys, hs = g.pose(np.array([10.0, 60.0]))
    assert xs.shape == (2,) and hs.tolist() == [0.3, 0.3]


@pytest.mark.parametrize("k", [0.01, -0.02, 1e-12, 0.0])
def test_arc_closed_form(k):
    g = Arc(0.0, 5.0, -3.0, 1.1, 100.0, k)
    s = np.linspace(0.0, 100.0, 11)
    x, y, h = g.pose(s)
    if abs(k) > 1e-9:
        xr = 5.0 + (np.sin(1.1 + k * s) - math.sin(1.1)) / k
        yr = -3.0 - (np.cos(1.1 + k * s) - math.cos(1.1)) / k
    else:
        xr, yr = 5.0 + s * math.cos(1.1), -3.0 + s * math.sin(1.1)
    np.testing.assert_allclose(x, xr, atol=1e-9)
    np.testing.assert_allclose(y, yr, atol=1e-9)
    np.testing.assert_allclose(h, 1.1 + k * s, atol=1e-15)
    assert g.curvature(3.0) == k


def test_arc_quarter_circle_radius_100():
    g = Arc(0.0, 0.0, 0.0, 0.0, 50.0 * math.pi, 0.01)
    x, y, h = end_pose(g)
    assert (x, y, h) == pytest.approx((100.0, 100.0, math.pi / 2), abs=1e-12)


@pytest.mark.parametrize(
    "k0,k1,length", [(0.0, 0.007, 50.0), (0.007, 0.0, 32.9), (-0.01, 0.02, 120.0), (0.05, 0.05, 60.0), (0.0, 0.2, 40.0)]
)
def test_spiral_matches_numeric_heading_integration(k0, k1, length):
    g = Spiral(2.0, 1.0, -1.0, 0.4, length, k0, k1)
    rate = (k1 - k0) / length
    for s_rel in (0.0, length / 3, length):
        x, y, h = g.pose(2.0 + s_rel)
        xi, yi = _integrate_heading(lambda u: 0.4 + k0 * u + 0.5 * rate * u * u, s_rel)
        assert x == pytest.approx(1.0 + xi, abs=1e-9)
        assert y == pytest.approx(-1.0 + yi, abs=1e-9)
        assert h == pytest.approx(0.4 + k0 * s_rel + 0.5 * rate * s_rel**2, abs=1e-14)
        assert g.curvature(2.0 + s_rel) == pytest.approx(k0 + rate * s_rel, abs=1e-15)


def test_spiral_vs_fresnel_closed_form():
    special = pytest.importorskip("scipy.special")
    length, k1 = 80.0, 0.02
    g = Spiral(0.0, 0.0, 0.0, 0.0, length, 0.0, k1)
    a = math.sqrt(math.pi * length / k1)  # clothoid scale: θ = (π/2)(s/a)²
    s = np.linspace(0.0, length, 9)
    S, C = special.fresnel(s / a)
    x, y, _ = g.pose(s)
    np.testing.assert_allclose(x, a * C, atol=1e-10)
    np.testing.assert_allclose(y, a * S, atol=1e-10)


def test_spiral_arrays_keep_shape():
    g = Spiral(0.0, 0.0, 0.0, 0.0, 10.0, 0.0, 0.1)
    x, y, h = g.pose(np.zeros((2, 3)))
    assert x.shape == y.shape == h.shape == (2, 3)


@pytest.mark.parametrize("p_range,scale", [("arcLength", 1.0), ("normalized", 40.0)])
def test_param_poly3_modes(p_range, scale):
    length = 40.0
    # Same curve in both parametrisations: coefficients of p^n scale with length^n.
    cU, cV, dV = -1e-3, 4e-3, -5e-5
    g = ParamPoly3(
        0.0, 3.0, 4.0, 0.5, length,
        0.0, 1.0 * scale, cU * scale**2, 0.0,
        0.0, 0.0, cV * scale**2, dV * scale**3, p_range,
    )
    ds = 25.0
    u = ds + cU * ds**2
    v = cV * ds**2 + dV * ds**3
    du, dv = 1.0 + 2 * cU * ds, 2 * cV * ds + 3 * dV * ds**2
    x, y, h = g.pose(ds)
    assert x == pytest.approx(3.0 + math.cos(0.5) * u - math.sin(0.5) * v, abs=1e-12)
    assert y == pytest.approx(4.0 + math.sin(0.5) * u + math.cos(0.5) * v, abs=1e-12)
    assert h == pytest.approx(0.5 + math.atan2(dv, du), abs=1e-12)
    k = (du * (2 * cV + 6 * dV * ds) - dv * 2 * cU) / (du * du + dv * dv) ** 1.5
    assert g.curvature(ds) == pytest.approx(k, rel=1e-9)


def test_param_poly3_rejects_unknown_prange():
    with pytest.raises(ValueError):
        ParamPoly3(0, 0, 0, 0, 1.0, 0, 1, 0, 0, 0, 0, 0, 0, "bogus")


def test_poly3_is_arc_length_parametrised():
    g = Poly3(0.0, 0.0, 0.0, 0.0, 30.0, 0.0, 0.0, 0.01, -1e-4)
    s = np.linspace(0.0, 30.0, 301)
    x, y, h = g.pose(s)
    seg = np.hypot(np.diff(x), np.diff(y))
    np.testing.assert_allclose(np.cumsum(seg)[-1], 30.0, atol=2e-4)  # chord sum ~ arc length
    np.testing.assert_allclose(y, 0.01 * x**2 - 1e-4 * x**3, atol=1e-12)
    np.testing.assert_allclose(h, np.arctan(0.02 * x - 3e-4 * x**2), atol=1e-12)


def test_place_makes_tangent_continuous_start():
    g = place(param_poly3(20.0, bU=1.0, bV=0.5, cV=0.01), 5.0, 1.0, 2.0, 0.7)
    x, y, h = g.pose(5.0)
    assert (x, y, h) == pytest.approx((1.0, 2.0, 0.7), abs=1e-12)
    g2 = place(spiral(10.0, 0.0, 0.1), 0.0, -1.0, 1.0, -0.2)
    assert g2.pose(0.0) == pytest.approx((-1.0, 1.0, -0.2), abs=1e-12)


def test_cubic_profile_records_and_before_first():
    p = CubicProfile((10.0, 0.0), ((5.0, 0.0, 0.0, 0.0), (1.0, 2.0, 0.0, 0.0)))  # unsorted on purpose
    assert p(2.0) == 5.0
    assert p(10.0) == 5.0 and p(12.0) == 5.0
    assert p.derivative(2.0) == 2.0
    z = CubicProfile((5.0,), ((1.0, 1.0, 0.0, 0.0),), before_first="zero")
    assert z(4.0) == 0.0 and z(6.0) == 2.0
    assert CubicProfile()(3.0) == 0.0
