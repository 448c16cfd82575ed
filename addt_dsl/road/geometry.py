"""OpenDRIVE planView primitives and cubic s-profiles as pure, vectorised functions.

Every primitive is a frozen dataclass placed at ``(s0, x0, y0, hdg0)`` with a ``length``.
Its methods take the *road* coordinate ``s`` [m] (scalar or numpy array) and return
numpy arrays (or Python floats for scalar input):

* ``pose(s) -> (x, y, heading)``  [m, m, rad], heading of the tangent in the xy plane
* ``curvature(s)``                [1/m], positive = turning left (counter-clockwise)

Evaluation outside ``[s0, s0 + length]`` extrapolates the same formula; the road selects
the primitive, so that only happens for tiny float overshoots.

The module also offers factory functions (``line``, ``arc``, ``spiral``, ``poly3``,
``param_poly3``) that build primitives at the origin; ``place`` moves one so that it
starts at a given pose (used to chain inline roads tangent-continuously).
"""

from __future__ import annotations

import bisect
import dataclasses
import math
from dataclasses import dataclass, field
from typing import Union

import numpy as np

from addt_dsl.kernel import atan, atan2, matmul
from addt_dsl.kernel import pow  # the C library's (numpy's own may differ by machine)

from .limits import MAX_GEOMETRY_TURN_RAD, RoadLimitError, beyond

ArrayLike = Union[float, np.ndarray]

# Gauss-Legendre rule used for the clothoid and poly3 arc-length integrals. 16 nodes
# integrate cos/sin of a quadratic phase to machine precision as long as the phase
# changes by <= ~0.5 rad per sub-interval, which ``_n_sub`` guarantees.
_GL_NODES, _GL_WEIGHTS = np.polynomial.legendre.leggauss(16)
_MAX_PHASE_PER_SUB_RAD = 0.5


def _out(value: np.ndarray, scalar: bool):
    """Return a Python float for scalar queries, the array otherwise."""
    return float(value) if scalar else value


def _composite_rule(n_sub: int) -> tuple[np.ndarray, np.ndarray]:
    """Nodes in [0, 1] and weights (summing to 1) of an n_sub-panel Gauss-Legendre rule."""
    j = np.arange(n_sub)[:, None]
    nodes = ((j + (_GL_NODES[None, :] + 1.0) / 2.0) / n_sub).ravel()
    weights = np.tile(_GL_WEIGHTS / (2.0 * n_sub), n_sub)
    return nodes, weights


def _check_turn(kind: str, max_abs_curvature: float, length: float) -> float:
    """The geometry's largest possible heading change, refused beyond MAX_GEOMETRY_TURN_RAD:
    sampling and the clothoid's integration rule grow with it (a 1e12 /m arc must not
    ask for petabytes)."""
    turn = max_abs_curvature * length
    if not turn <= MAX_GEOMETRY_TURN_RAD:
        raise RoadLimitError(f"{kind} with |curvature| up to {max_abs_curvature:.6g} /m over {length:.6g} m: its turn "
                             "of " + beyond("MAX_GEOMETRY_TURN_RAD", turn, MAX_GEOMETRY_TURN_RAD, "rad",
                                            "split the curve into several geometries"))
    return turn


def _check_finite(name: str, **values: float) -> None:
    for key, value in values.items():
        if not math.isfinite(value):
            raise ValueError(f"{name}: {key} must be finite, got {value!r}")


@dataclass(frozen=True)
class Line:
    """Straight segment."""

    s0: float
    x0: float
    y0: float
    hdg0: float
    length: float

    kind = "line"

    def pose(self, s: ArrayLike):
        scalar = np.ndim(s) == 0
        ds = np.asarray(s, dtype=float) - self.s0
        x = self.x0 + ds * math.cos(self.hdg0)
        y = self.y0 + ds * math.sin(self.hdg0)
        h = np.full_like(ds, self.hdg0)
        return _out(x, scalar), _out(y, scalar), _out(h, scalar)

    def curvature(self, s: ArrayLike):
        scalar = np.ndim(s) == 0
        return _out(np.zeros_like(np.asarray(s, dtype=float)), scalar)


@dataclass(frozen=True)
class Arc:
    """Circular arc of constant ``curvature_per_m`` [1/m] (positive = left turn)."""

    s0: float
    x0: float
    y0: float
    hdg0: float
    length: float
    curvature_per_m: float

    kind = "arc"

    def __post_init__(self) -> None:
        _check_turn(self.kind, abs(self.curvature_per_m), self.length)

    def pose(self, s: ArrayLike):
        scalar = np.ndim(s) == 0
        ds = np.asarray(s, dtype=float) - self.s0
        half = 0.5 * self.curvature_per_m * ds
        # Chord form: |chord| = ds * sinc(k ds / 2) along hdg0 + k ds / 2. Stable for
        # k -> 0, unlike (sin(h0 + k ds) - sin h0) / k.
        chord = ds * np.sinc(half / np.pi)
        x = self.x0 + chord * np.cos(self.hdg0 + half)
        y = self.y0 + chord * np.sin(self.hdg0 + half)
        h = self.hdg0 + 2.0 * half
        return _out(x, scalar), _out(y, scalar), _out(h, scalar)

    def curvature(self, s: ArrayLike):
        scalar = np.ndim(s) == 0
        k = np.full_like(np.asarray(s, dtype=float), self.curvature_per_m)
        return _out(k, scalar)


@dataclass(frozen=True)
class Spiral:
    """Clothoid: curvature linear in s from ``curv_start`` to ``curv_end`` [1/m].

    Position is the Fresnel-type integral x + iy = ∫ exp(i θ(u)) du with
    θ(u) = hdg0 + k0 u + ½ k' u², evaluated by composite Gauss-Legendre quadrature.
    This needs no special functions and stays accurate for every k' (including the
    arc-like k' -> 0 case where the textbook Fresnel substitution cancels badly).
    """

    s0: float
    x0: float
    y0: float
    hdg0: float
    length: float
    curv_start: float
    curv_end: float
    _nodes: np.ndarray = field(init=False, repr=False, compare=False)
    _weights: np.ndarray = field(init=False, repr=False, compare=False)

    kind = "spiral"

    def __post_init__(self) -> None:
        if not self.length >= 0.0:
            raise ValueError(f"spiral length must be >= 0 m, got {self.length!r}")
        max_turn = _check_turn(self.kind, max(abs(self.curv_start), abs(self.curv_end)), self.length)
        n_sub = max(1, math.ceil(max_turn / _MAX_PHASE_PER_SUB_RAD))
        nodes, weights = _composite_rule(n_sub)
        object.__setattr__(self, "_nodes", nodes)
        object.__setattr__(self, "_weights", weights)

    @property
    def curv_rate(self) -> float:
        """dκ/ds [1/m²] (0 for a degenerate zero-length spiral)."""
        if self.length == 0.0:
            return 0.0
        return (self.curv_end - self.curv_start) / self.length

    def pose(self, s: ArrayLike):
        scalar = np.ndim(s) == 0
        ds = np.asarray(s, dtype=float).ravel() - self.s0
        u = ds[:, None] * self._nodes[None, :]
        phase = self.curv_start * u + 0.5 * self.curv_rate * u * u
        c = ds * matmul(np.cos(phase), self._weights)
        sn = ds * matmul(np.sin(phase), self._weights)
        ch, sh = math.cos(self.hdg0), math.sin(self.hdg0)
        x = self.x0 + ch * c - sh * sn
        y = self.y0 + sh * c + ch * sn
        h = self.hdg0 + self.curv_start * ds + 0.5 * self.curv_rate * ds * ds
        if scalar:
            return float(x[0]), float(y[0]), float(h[0])
        shape = np.shape(s)
        return x.reshape(shape), y.reshape(shape), h.reshape(shape)

    def curvature(self, s: ArrayLike):
        scalar = np.ndim(s) == 0
        ds = np.asarray(s, dtype=float) - self.s0
        return _out(self.curv_start + self.curv_rate * ds, scalar)


@dataclass(frozen=True)
class Poly3:
    """Deprecated OpenDRIVE cubic: v(u) = a + b u + c u² + d u³ in the local (u, v) frame.

    ``s`` is arc length, so u(s) is found by Newton iteration on the arc-length integral.
    """

    s0: float
    x0: float
    y0: float
    hdg0: float
    length: float
    a: float
    b: float
    c: float
    d: float
    _nodes: np.ndarray = field(init=False, repr=False, compare=False)
    _weights: np.ndarray = field(init=False, repr=False, compare=False)

    kind = "poly3"

    def __post_init__(self) -> None:
        nodes, weights = _composite_rule(4)
        object.__setattr__(self, "_nodes", nodes)
        object.__setattr__(self, "_weights", weights)

    def _dv(self, u):
        return self.b + 2.0 * self.c * u + 3.0 * self.d * u * u

    def _arc_length(self, u: np.ndarray) -> np.ndarray:
        w = u[:, None] * self._nodes[None, :]
        return u * matmul(np.sqrt(1.0 + self._dv(w) ** 2), self._weights)

    def _u_of(self, ds: np.ndarray) -> np.ndarray:
        u = ds / math.sqrt(1.0 + self.b * self.b)
        for _ in range(30):
            step = (self._arc_length(u) - ds) / np.sqrt(1.0 + self._dv(u) ** 2)
            u = u - step
            if np.all(np.abs(step) < 1e-13 * (1.0 + np.abs(u))):
                break
        return u

    def pose(self, s: ArrayLike):
        scalar = np.ndim(s) == 0
        ds = np.asarray(s, dtype=float).ravel() - self.s0
        u = self._u_of(ds)
        v = self.a + u * (self.b + u * (self.c + u * self.d))
        ch, sh = math.cos(self.hdg0), math.sin(self.hdg0)
        x = self.x0 + ch * u - sh * v
        y = self.y0 + sh * u + ch * v
        h = self.hdg0 + atan.over(self._dv(u))
        if scalar:
            return float(x[0]), float(y[0]), float(h[0])
        shape = np.shape(s)
        return x.reshape(shape), y.reshape(shape), h.reshape(shape)

    def curvature(self, s: ArrayLike):
        scalar = np.ndim(s) == 0
        ds = np.asarray(s, dtype=float).ravel() - self.s0
        u = self._u_of(ds)
        k = (2.0 * self.c + 6.0 * self.d * u) / (1.0 + self._dv(u) ** 2) ** 1.5
        return float(k[0]) if scalar else k.reshape(np.shape(s))


@dataclass(frozen=True)
class ParamPoly3:
    """Parametric cubic u(p), v(p) in the local frame.

    ``p_range``: ``"arcLength"`` (p = s - s0, p in [0, length]) or ``"normalized"``
    (p = (s - s0) / length, p in [0, 1]). As in the standard (and the ASAM checker), the
    s -> p mapping is linear; p is not re-parametrised to exact arc length.
    """

    s0: float
    x0: float
    y0: float
    hdg0: float
    length: float
    aU: float
    bU: float
    cU: float
    dU: float
    aV: float
    bV: float
    cV: float
    dV: float
    p_range: str = "normalized"

    kind = "paramPoly3"

    def __post_init__(self) -> None:
        if self.p_range not in ("arcLength", "normalized"):
            raise ValueError(f"paramPoly3 pRange must be 'arcLength' or 'normalized', got {self.p_range!r}")
        if self.p_range == "normalized" and not self.length > 0.0:
            raise ValueError("normalized paramPoly3 needs length > 0 m")

    def _p(self, s: ArrayLike) -> np.ndarray:
        ds = np.asarray(s, dtype=float) - self.s0
        return ds / self.length if self.p_range == "normalized" else ds

    def pose(self, s: ArrayLike):
        scalar = np.ndim(s) == 0
        p = self._p(s)
        u = self.aU + p * (self.bU + p * (self.cU + p * self.dU))
        v = self.aV + p * (self.bV + p * (self.cV + p * self.dV))
        du = self.bU + p * (2.0 * self.cU + 3.0 * self.dU * p)
        dv = self.bV + p * (2.0 * self.cV + 3.0 * self.dV * p)
        ch, sh = math.cos(self.hdg0), math.sin(self.hdg0)
        x = self.x0 + ch * u - sh * v
        y = self.y0 + sh * u + ch * v
        h = self.hdg0 + atan2.over(dv, du)
        return _out(x, scalar), _out(y, scalar), _out(h, scalar)

    def curvature(self, s: ArrayLike):
        # Curvature is invariant under the (linear) choice of parameter.
        scalar = np.ndim(s) == 0
        p = self._p(s)
        du = self.bU + p * (2.0 * self.cU + 3.0 * self.dU * p)
        dv = self.bV + p * (2.0 * self.cV + 3.0 * self.dV * p)
        ddu = 2.0 * self.cU + 6.0 * self.dU * p
        ddv = 2.0 * self.cV + 6.0 * self.dV * p
        k = (du * ddv - dv * ddu) / pow.over(du * du + dv * dv, 1.5)
        return _out(k, scalar)


Geometry = Union[Line, Arc, Spiral, Poly3, ParamPoly3]


def end_pose(geom: Geometry) -> tuple[float, float, float]:
    """Pose ``(x, y, heading)`` [m, m, rad] at the end of a primitive."""
    return geom.pose(geom.s0 + geom.length)


def start_tangent_offset(geom: Geometry) -> float:
    """Angle [rad] between ``hdg0`` and the actual start tangent (non-zero for cubics with b != 0)."""
    if isinstance(geom, ParamPoly3):
        return math.atan2(geom.bV, geom.bU)
    if isinstance(geom, Poly3):
        return math.atan(geom.b)
    return 0.0


def place(geom: Geometry, s0: float, x0: float, y0: float, heading: float) -> Geometry:
    """Copy of ``geom`` whose curve starts at ``(x0, y0)`` with tangent ``heading`` [rad].

    Cubics with a start offset (``a``/``aU``/``aV`` != 0) are shifted so that the *curve*
    (not the local origin) starts at (x0, y0).
    """
    hdg0 = heading - start_tangent_offset(geom)
    moved = dataclasses.replace(geom, s0=s0, x0=0.0, y0=0.0, hdg0=hdg0)
    x_start, y_start, _ = moved.pose(s0)
    return dataclasses.replace(moved, x0=x0 - x_start, y0=y0 - y_start)


# --- factories for code-built (inline) roads: primitives at the origin, placed later ---


def line(length_m: float) -> Line:
    _check_finite("line", length_m=length_m)
    if not length_m > 0.0:
        raise ValueError(f"line length must be > 0 m, got {length_m!r}")
    return Line(0.0, 0.0, 0.0, 0.0, float(length_m))


def arc(length_m: float, curvature_per_m: float) -> Arc:
    """Arc of ``length_m`` [m]; ``curvature_per_m`` [1/m] = 1 / radius, positive turns left."""
    _check_finite("arc", length_m=length_m, curvature_per_m=curvature_per_m)
    if not length_m > 0.0:
        raise ValueError(f"arc length must be > 0 m, got {length_m!r}")
    return Arc(0.0, 0.0, 0.0, 0.0, float(length_m), float(curvature_per_m))


def spiral(length_m: float, curv_start: float, curv_end: float) -> Spiral:
    """Clothoid of ``length_m`` [m] with curvature going linearly curv_start -> curv_end [1/m]."""
    _check_finite("spiral", length_m=length_m, curv_start=curv_start, curv_end=curv_end)
    if not length_m > 0.0:
        raise ValueError(f"spiral length must be > 0 m, got {length_m!r}")
    return Spiral(0.0, 0.0, 0.0, 0.0, float(length_m), float(curv_start), float(curv_end))


def poly3(length_m: float, a: float, b: float, c: float, d: float) -> Poly3:
    _check_finite("poly3", length_m=length_m, a=a, b=b, c=c, d=d)
    if not length_m > 0.0:
        raise ValueError(f"poly3 length must be > 0 m, got {length_m!r}")
    return Poly3(0.0, 0.0, 0.0, 0.0, float(length_m), float(a), float(b), float(c), float(d))


def param_poly3(
    length_m: float,
    aU: float = 0.0,
    bU: float = 1.0,
    cU: float = 0.0,
    dU: float = 0.0,
    aV: float = 0.0,
    bV: float = 0.0,
    cV: float = 0.0,
    dV: float = 0.0,
    p_range: str = "arcLength",
) -> ParamPoly3:
    _check_finite("paramPoly3", length_m=length_m, aU=aU, bU=bU, cU=cU, dU=dU, aV=aV, bV=bV, cV=cV, dV=dV)
    if not length_m > 0.0:
        raise ValueError(f"paramPoly3 length must be > 0 m, got {length_m!r}")
    return ParamPoly3(
        0.0, 0.0, 0.0, 0.0, float(length_m),
        float(aU), float(bU), float(cU), float(dU),
        float(aV), float(bV), float(cV), float(dV), p_range,
    )


@dataclass(frozen=True)
class CubicProfile:
    """Piecewise cubic f(s) = a + b ds + c ds² + d ds³, ds = s - start of the active record.

    Used for elevation [m], superelevation [rad], laneOffset [m] and lane widths [m]
    (widths use s relative to the lane-section start). ``before_first`` selects what
    happens for s before the first record: ``"extrapolate"`` the first record (elevation,
    as the ASAM checker does) or ``"zero"`` (laneOffset).
    """

    starts: tuple[float, ...] = ()
    coeffs: tuple[tuple[float, float, float, float], ...] = ()
    before_first: str = "extrapolate"
    _starts: np.ndarray = field(init=False, repr=False, compare=False)
    _coeffs: np.ndarray = field(init=False, repr=False, compare=False)
    starts_sorted: tuple = field(init=False, repr=False, compare=False)
    coeffs_sorted: tuple = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if len(self.starts) != len(self.coeffs):
            raise ValueError("CubicProfile: starts and coeffs differ in length")
        order = np.argsort(np.asarray(self.starts, dtype=float), kind="stable")
        object.__setattr__(self, "_starts", np.asarray(self.starts, dtype=float)[order])
        object.__setattr__(self, "_coeffs", np.asarray(self.coeffs, dtype=float).reshape(-1, 4)[order])
        object.__setattr__(self, "starts_sorted", tuple(float(v) for v in self._starts))
        object.__setattr__(self, "coeffs_sorted", tuple(tuple(float(v) for v in row) for row in self._coeffs))

    @staticmethod
    def constant(value: float) -> "CubicProfile":
        return CubicProfile((0.0,), ((float(value), 0.0, 0.0, 0.0),))

    def _locate(self, s: np.ndarray):
        idx = np.searchsorted(self._starts, s, side="right") - 1
        before = idx < 0
        idx = np.clip(idx, 0, None)
        return idx, s - self._starts[idx], before

    def value_and_rate(self, s: float) -> tuple[float, float]:
        """Scalar fast path: ``(f(s), df/ds)`` with plain floats (hot in per-step queries)."""
        starts = self.starts_sorted
        if not starts:
            return 0.0, 0.0
        i = bisect.bisect_right(starts, s) - 1
        if i < 0:
            if self.before_first == "zero":
                return 0.0, 0.0
            i = 0
        a, b, c, d = self.coeffs_sorted[i]
        ds = s - starts[i]
        return a + ds * (b + ds * (c + ds * d)), b + ds * (2.0 * c + 3.0 * d * ds)

    def __call__(self, s: ArrayLike):
        scalar = np.ndim(s) == 0
        s_arr = np.asarray(s, dtype=float)
        if len(self._starts) == 0:
            return _out(np.zeros_like(s_arr), scalar)
        idx, ds, before = self._locate(s_arr)
        a, b, c, d = (self._coeffs[idx, i] for i in range(4))
        value = a + ds * (b + ds * (c + ds * d))
        if self.before_first == "zero":
            value = np.where(before, 0.0, value)
        return _out(value, scalar)

    def derivative(self, s: ArrayLike):
        """df/ds."""
        scalar = np.ndim(s) == 0
        s_arr = np.asarray(s, dtype=float)
        if len(self._starts) == 0:
            return _out(np.zeros_like(s_arr), scalar)
        idx, ds, before = self._locate(s_arr)
        b, c, d = (self._coeffs[idx, i] for i in (1, 2, 3))
        value = b + ds * (2.0 * c + 3.0 * d * ds)
        if self.before_first == "zero":
            value = np.where(before, 0.0, value)
        return _out(value, scalar)
