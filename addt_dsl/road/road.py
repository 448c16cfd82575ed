"""A single OpenDRIVE road: reference line, profiles, lane sections and projection.

All queries accept a scalar ``s`` [m] (returning Python floats) or a numpy array
(returning arrays of the same shape). ``s`` must lie in ``[0, length]`` (a 1e-6 m float
slack is clamped); anything else raises ``ValueError`` rather than extrapolating.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from addt_dsl.kernel import atan2, matmul

from .geometry import CubicProfile, Geometry
from .lanes import DRIVING_TYPES, LaneSection, lanes_at_t_array
from .limits import MAX_COORDINATE_M, MAX_ROAD_LENGTH_M, MAX_ROAD_SAMPLES, RoadLimitError, beyond

S_SLACK_M = 1e-6  # tolerated overshoot of s beyond [0, length] (float noise in files)
ON_ROAD_LONG_TOL_M = 1e-6  # projection residual along the road beyond which a point is "off the end"
_SAMPLE_STEP_M = 4.0  # coarse projection grid step, refined where curvature is high
_MAX_SAMPLE_TURN_RAD = 0.1  # max heading change between coarse samples
_PROJECT_CHUNK = 2048  # points per block in the (points x samples) distance matrix
_NEWTON_ITERS = 12
_SECTION_SNAP_M = 1e-9


@dataclass(frozen=True)
class RoadLink:
    """``<predecessor>``/``<successor>`` of a road: ``element_type`` is "road" or "junction";
    ``contact_point`` ("start"/"end") is the touched end of the linked road (None for junctions)."""

    element_type: str
    element_id: str
    contact_point: Optional[str] = None


def _scalar_or(value: np.ndarray, scalar: bool):
    return float(value) if scalar else value


@dataclass(frozen=True)
class Signal:
    """``<signals><signal>`` of a road: at station ``s`` [m], offset ``t`` [m]; ``orientation``
    "+" faces traffic driving along +s, "-" against, "none" both; ``dynamic`` for traffic lights."""

    id: str
    s: float
    t: float
    name: str = ""
    type: str = ""
    subtype: str = ""
    dynamic: bool = False
    orientation: str = "none"
    # `<validity fromLane toLane>`: the lanes the signal governs (inclusive; None: every lane
    # of the direction it faces).
    validity: Optional[tuple[int, int]] = None
    # Placed by a `<signalReference>` on another road (`RoadNetwork.placements`): `s`, `t`,
    # `orientation` and `validity` are the reference's, the rest the signal's.
    reference: bool = False


@dataclass(frozen=True)
class SignalRef:
    """``<signals><signalReference>`` (OpenDRIVE 1.6, 13.8): the existing signal ``id`` placed
    on this road at station ``s`` [m], offset ``t`` [m], with its own ``orientation`` and
    ``validity`` (as `Signal`'s)."""

    id: str
    s: float
    t: float
    orientation: str = "none"
    validity: Optional[tuple[int, int]] = None


@dataclass(frozen=True)
class Controller:
    """``<controller>``: signals that switch together (``<control signalId>``), by id."""

    id: str
    name: str = ""
    signal_ids: tuple[str, ...] = ()


@dataclass(frozen=True)
class Road:
    id: str
    length: float
    geometries: tuple[Geometry, ...]
    sections: tuple[LaneSection, ...]
    offset_profile: CubicProfile = field(default_factory=lambda: CubicProfile(before_first="zero"))
    elevation_profile: CubicProfile = field(default_factory=CubicProfile)
    superelevation_profile: CubicProfile = field(default_factory=CubicProfile)
    name: str = ""
    junction: str = "-1"
    rule: str = "RHT"
    predecessor: Optional[RoadLink] = None
    successor: Optional[RoadLink] = None
    signals: tuple[Signal, ...] = ()
    signal_refs: tuple[SignalRef, ...] = ()
    # <type><speed max>: (start station [m], speed limit [m/s]) in order of s.
    speed_limits: tuple[tuple[float, float], ...] = ()
    _geom_starts: np.ndarray = field(init=False, repr=False, compare=False)
    _section_starts: np.ndarray = field(init=False, repr=False, compare=False)
    _section_starts_t: tuple = field(init=False, repr=False, compare=False)
    _geom_starts_t: tuple = field(init=False, repr=False, compare=False)
    _sample_s: np.ndarray = field(init=False, repr=False, compare=False)
    _sample_xy: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not self.geometries:
            raise ValueError(f"road {self.id}: no planView geometry")
        if not self.sections:
            raise ValueError(f"road {self.id}: no lane section")
        if not (self.length > 0.0 and math.isfinite(self.length)):
            raise ValueError(f"road {self.id}: length must be > 0 m, got {self.length!r}")
        if self.length > MAX_ROAD_LENGTH_M:
            raise RoadLimitError(f"road {self.id}: length " + beyond(
                "MAX_ROAD_LENGTH_M", self.length, MAX_ROAD_LENGTH_M, "m", "split it into consecutive roads"))
        object.__setattr__(self, "_geom_starts", np.array([g.s0 for g in self.geometries]))
        object.__setattr__(self, "_section_starts", np.array([sec.s0 for sec in self.sections]))
        object.__setattr__(self, "_section_starts_t", tuple(sec.s0 for sec in self.sections))
        object.__setattr__(self, "_geom_starts_t", tuple(g.s0 for g in self.geometries))
        sample_s = self._coarse_samples()
        x, y, _ = self.reference_pose(sample_s)
        reach = float(np.max(np.abs(np.concatenate([x, y]))))
        if not reach <= MAX_COORDINATE_M:  # also catches NaN
            raise RoadLimitError(f"road {self.id}: reference line distance from the map origin: " + beyond(
                "MAX_COORDINATE_M", reach, MAX_COORDINATE_M, "m"))
        object.__setattr__(self, "_sample_s", sample_s)
        object.__setattr__(self, "_sample_xy", np.stack([x, y], axis=1))

    # ------------------------------------------------------------------ helpers

    def _coarse_samples(self) -> np.ndarray:
        """Sample s every 4 m, and every 0.1 rad of heading where the road bends. The count
        is known before anything is allocated: a road that would need more than
        MAX_ROAD_SAMPLES is refused (a curvature of 1e12 /m must not ask for petabytes)."""
        spans = []
        ends = list(self._geom_starts[1:]) + [self.length]
        for i, (geom, end) in enumerate(zip(self.geometries, ends)):
            start = max(0.0, min(geom.s0, self.length))
            end = max(start, min(end, self.length))
            if end <= start:
                continue
            probe = np.linspace(start, end, 33)
            with np.errstate(all="ignore"):
                k_max = float(np.max(np.abs(geom.curvature(probe))))
            if not math.isfinite(k_max):
                raise RoadLimitError(f"road {self.id}: the {geom.kind} geometry at s={geom.s0:.6g} m has no finite "
                                     "curvature (a degenerate tangent)", geometry=i)
            n = max(2, math.ceil((end - start) / _SAMPLE_STEP_M),
                    math.ceil((end - start) * k_max / _MAX_SAMPLE_TURN_RAD)) + 1
            spans.append((i, geom, start, end, n))
        total = sum(n for *_, n in spans)
        if total > MAX_ROAD_SAMPLES:
            i, geom, *_ = max(spans, key=lambda sp: sp[-1])
            raise RoadLimitError(f"road {self.id}: sampling it needs {total:.6g} points (the {geom.kind} geometry at "
                                 f"s={geom.s0:.6g} m bends too sharply for its length); " + beyond(
                                     "MAX_ROAD_SAMPLES", total, MAX_ROAD_SAMPLES, "samples"), geometry=i)
        pieces = [np.linspace(start, end, n) for _, _, start, end, n in spans]
        return np.unique(np.concatenate(pieces + [np.array([0.0, self.length])]))

    def _s(self, s) -> tuple[np.ndarray, bool]:
        if isinstance(s, (float, int)):  # fast path for per-step scalar queries
            if not -S_SLACK_M <= s <= self.length + S_SLACK_M:
                raise ValueError(f"road {self.id}: s={s!r} m outside [0, {self.length}] m")
            return np.float64(min(max(float(s), 0.0), self.length)), True
        scalar = np.ndim(s) == 0
        s_arr = np.asarray(s, dtype=float)
        bad = ~((s_arr >= -S_SLACK_M) & (s_arr <= self.length + S_SLACK_M))
        if np.any(bad):
            first = float(s_arr[bad].flat[0]) if s_arr.ndim else float(s_arr)
            raise ValueError(f"road {self.id}: s={first!r} m outside [0, {self.length}] m")
        return np.clip(s_arr, 0.0, self.length), scalar

    def _geom_index(self, s: np.ndarray) -> np.ndarray:
        idx = np.searchsorted(self._geom_starts, s, side="right") - 1
        return np.clip(idx, 0, len(self.geometries) - 1)

    def _section_index(self, s: np.ndarray) -> np.ndarray:
        idx = np.searchsorted(self._section_starts, s, side="right") - 1
        return np.clip(idx, 0, len(self.sections) - 1)

    def _by_geometry(self, s: np.ndarray, method: str, n_out: int):
        """Evaluate ``geom.<method>(s)`` with each s routed to its primitive."""
        if np.ndim(s) == 0:
            i = max(0, bisect.bisect_right(self._geom_starts_t, float(s)) - 1)
            return getattr(self.geometries[i], method)(float(s))
        idx = self._geom_index(s)
        if idx.ndim == 0 or np.all(idx == idx.flat[0]):
            res = getattr(self.geometries[int(idx.flat[0]) if idx.size else 0], method)(s)
            return res
        outs = [np.empty(s.shape) for _ in range(n_out)]
        for i in np.unique(idx):
            m = idx == i
            res = getattr(self.geometries[int(i)], method)(s[m])
            res = res if n_out > 1 else (res,)
            for out, r in zip(outs, res):
                out[m] = r
        return tuple(outs) if n_out > 1 else outs[0]

    # --------------------------------------------------------------- reference line

    def reference_pose(self, s):
        """Reference-line pose ``(x, y, heading)`` [m, m, rad] at ``s`` [m]."""
        s_arr, scalar = self._s(s)
        x, y, h = self._by_geometry(s_arr, "pose", 3)
        if scalar:
            return float(x), float(y), float(h)
        return np.asarray(x), np.asarray(y), np.asarray(h)

    def curvature(self, s):
        """Reference-line curvature [1/m] at ``s`` [m], positive = turning left."""
        s_arr, scalar = self._s(s)
        return _scalar_or(np.asarray(self._by_geometry(s_arr, "curvature", 1)), scalar)

    def elevation(self, s):
        """Reference-line height z [m] at ``s`` [m] (0 without an elevationProfile)."""
        s_arr, scalar = self._s(s)
        return _scalar_or(np.asarray(self.elevation_profile(s_arr)), scalar)

    def superelevation(self, s):
        """Road roll angle [rad] at ``s`` [m]. Parsed and reported only: lateral
        positions are computed in the xy plane (t not scaled by cos(roll))."""
        s_arr, scalar = self._s(s)
        return _scalar_or(np.asarray(self.superelevation_profile(s_arr)), scalar)

    def lane_offset_at(self, s):
        """laneOffset [m]: t of the centre lane (lane 0) at ``s`` [m]."""
        s_arr, scalar = self._s(s)
        return _scalar_or(np.asarray(self.offset_profile(s_arr)), scalar)

    def point_at(self, s, t):
        """World ``(x, y)`` [m] of road coordinates ``(s, t)`` [m] (t positive left)."""
        x, y, h = self.reference_pose(s)
        return x - np.sin(h) * t, y + np.cos(h) * t

    # ------------------------------------------------------------------- lanes

    def section_at(self, s: float) -> LaneSection:
        s_arr, _ = self._s(s)
        return self.sections[int(self._section_index(s_arr))]

    def lane_ids(self, s: float) -> tuple[int, ...]:
        """Lanes existing at ``s`` with width > 0, ordered left to right (n..1, -1..-m)."""
        s_arr, _ = self._s(s)
        sec = self.sections[int(self._section_index(s_arr))]
        ds = float(s_arr) - sec.s0
        return tuple(i for i in sec.lane_ids if float(sec.lane(i).width(ds)) > 1e-9)

    def driving_lane_ids(self, s: float) -> tuple[int, ...]:
        """:meth:`lane_ids` restricted to lanes of type ``driving``."""
        sec = self.section_at(s)
        return tuple(i for i in self.lane_ids(s) if sec.lane(i).type in DRIVING_TYPES)

    def lane_type(self, lane_id: int, s: float) -> str:
        sec = self.section_at(s)
        if lane_id == 0:
            return sec.center_type
        lane = sec.lane(int(lane_id))
        if lane is None:
            raise ValueError(f"road {self.id}: no lane {lane_id} at s={s} m (lanes {sec.lane_ids})")
        return lane.type

    def travel_direction(self, lane_id: int) -> int:
        """+1 if traffic on ``lane_id`` drives towards +s, -1 otherwise (from the road's
        ``rule``: RHT drives on right lanes (id < 0) along +s, LHT on left lanes)."""
        if lane_id == 0:
            raise ValueError("lane 0 carries no traffic")
        along = lane_id < 0 if self.rule == "RHT" else lane_id > 0
        return 1 if along else -1

    def _lane_t(self, lane_id: int, s_arr: np.ndarray, rates: bool):
        """(inner t, outer t[, inner rate, outer rate]) of ``lane_id``; NaN where absent."""
        lane_id = int(lane_id)
        if np.ndim(s_arr) == 0:
            return self._lane_t_scalar(lane_id, float(s_arr), rates)
        s1 = np.atleast_1d(s_arr)
        outs = [np.full(s1.shape, np.nan) for _ in range(4 if rates else 2)]
        sec_idx = self._section_index(s1)
        offset = np.asarray(self.offset_profile(s1))
        offset_rate = np.asarray(self.offset_profile.derivative(s1)) if rates else None
        for i in np.unique(sec_idx):
            sec = self.sections[int(i)]
            m = sec_idx == i
            if lane_id == 0:
                outs[0][m] = outs[1][m] = offset[m]
                if rates:
                    outs[2][m] = outs[3][m] = offset_rate[m]
                continue
            if sec.lane(lane_id) is None:
                continue
            side, k = (1 if lane_id > 0 else -1), abs(lane_id)
            ds = s1[m] - sec.s0
            borders = sec.side_borders(side, ds, offset[m])
            outs[0][m], outs[1][m] = borders[k - 1], borders[k]
            if rates:
                r = sec.side_border_rates(side, ds, offset_rate[m])
                outs[2][m], outs[3][m] = r[k - 1], r[k]
        return [o.reshape(np.shape(s_arr)) for o in outs]

    def section_at_scalar(self, s: float) -> LaneSection:
        """:meth:`section_at` for one float station (no numpy: a bisection, ~0.3 us)."""
        return self.sections[max(0, bisect.bisect_right(self._section_starts_t, s) - 1)]

    def _lane_t_scalar(self, lane_id: int, s: float, rates: bool):
        sec = self.section_at_scalar(s)
        t, rate = self.offset_profile.value_and_rate(s)
        nan = (math.nan,) * (4 if rates else 2)
        if lane_id == 0:
            return (t, t, rate, rate) if rates else (t, t)
        if sec.lane(lane_id) is None:
            return nan
        side = 1 if lane_id > 0 else -1
        lanes = sec.left if side > 0 else sec.right
        ds = s - sec.s0
        for lane in lanes[: abs(lane_id)]:
            w, w_rate = lane.width.value_and_rate(ds)
            inner, inner_rate = t, rate
            t, rate = t + side * w, rate + side * w_rate
        return (inner, t, inner_rate, rate) if rates else (inner, t)

    def _require_lane(self, lane_id: int, s_arr: np.ndarray, probe: np.ndarray) -> None:
        if np.any(np.isnan(probe)):
            bad = float(np.atleast_1d(s_arr)[np.isnan(np.atleast_1d(probe))][0])
            sec = self.sections[int(self._section_index(np.asarray(bad)))]
            raise ValueError(
                f"road {self.id}: no lane {lane_id} at s={bad} m (lane section at s={sec.s0} m has {sec.lane_ids})"
            )

    def lane_border_t(self, lane_id: int, s):
        """``(t_inner, t_outer)`` [m] of a lane's borders at ``s`` [m]."""
        s_arr, scalar = self._s(s)
        inner, outer = self._lane_t(lane_id, s_arr, rates=False)
        self._require_lane(lane_id, s_arr, inner)
        return (float(inner), float(outer)) if scalar else (inner, outer)

    def lane_width(self, lane_id: int, s):
        """Width [m] of ``lane_id`` at ``s`` [m] (0 for the centre lane)."""
        inner, outer = self.lane_border_t(lane_id, s)
        return abs(outer - inner) if np.ndim(inner) == 0 else np.abs(outer - inner)

    def lane_center_t(self, lane_id: int, s):
        """t [m] of the lane centre line at ``s`` [m]."""
        inner, outer = self.lane_border_t(lane_id, s)
        return 0.5 * (inner + outer)

    def lane_center(self, lane_id: int, s):
        """Pose ``(x, y, heading)`` [m, m, rad] of the lane centre line at ``s`` [m].

        ``heading`` is the tangent of the centre *curve* in the +s direction, i.e. the
        reference heading plus atan2(dt/ds, 1 - κ t); it differs from the reference
        heading where laneOffset or widths vary. It does not flip for lanes whose
        traffic drives against s (see :meth:`travel_direction`).
        """
        s_arr, scalar = self._s(s)
        inner, outer, r_in, r_out = self._lane_t(lane_id, s_arr, rates=True)
        self._require_lane(lane_id, s_arr, inner)
        t = 0.5 * (inner + outer)
        dt = 0.5 * (r_in + r_out)
        x, y, h = self.reference_pose(s_arr)
        k = self.curvature(s_arr)
        xc = x - np.sin(h) * t
        yc = y + np.cos(h) * t
        hc = h + atan2.over(dt, 1.0 - k * t)
        if scalar:
            return float(xc), float(yc), float(hc)
        return xc, yc, hc

    def lane_at(self, s, t) -> Optional[int]:
        """Lane containing lateral offset ``t`` [m] at ``s`` [m], or None (scalar version)."""
        ids = self.lanes_at(np.asarray([s], dtype=float), np.asarray([t], dtype=float))
        return int(ids[0]) or None

    def lanes_at(self, s: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Vectorised :meth:`lane_at`; 0 marks "outside all lanes"."""
        s_arr, _ = self._s(s)
        t = np.asarray(t, dtype=float)
        s1, t1 = np.atleast_1d(s_arr), np.atleast_1d(t)
        out = np.zeros(s1.shape, dtype=int)
        sec_idx = self._section_index(s1)
        offset = np.asarray(self.offset_profile(s1))
        for i in np.unique(sec_idx):
            m = sec_idx == i
            sec = self.sections[int(i)]
            out[m] = lanes_at_t_array(sec, s1[m] - sec.s0, offset[m], t1[m])
        return out.reshape(np.shape(t))

    def road_band_t(self, s):
        """``(t_min, t_max)`` [m]: outermost right and left lane borders at ``s`` [m]."""
        s_arr, scalar = self._s(s)
        s1 = np.atleast_1d(s_arr)
        lo, hi = np.empty(s1.shape), np.empty(s1.shape)
        sec_idx = self._section_index(s1)
        offset = np.asarray(self.offset_profile(s1))
        for i in np.unique(sec_idx):
            m = sec_idx == i
            sec = self.sections[int(i)]
            ds = s1[m] - sec.s0
            hi[m] = sec.side_borders(1, ds, offset[m])[-1]
            lo[m] = sec.side_borders(-1, ds, offset[m])[-1]
        if scalar:
            return float(lo[0]), float(hi[0])
        return lo.reshape(np.shape(s_arr)), hi.reshape(np.shape(s_arr))

    def paved_band_t(self, s: float) -> tuple[float, float]:
        """``(t_min, t_max)`` [m] at ``s`` [m]: the centre lane's t less (plus) the widths of the
        right (left) lanes whose type is not ``none`` (esmini's road width, beyond which an
        entity is off the road)."""
        sec = self.section_at(s)
        ds, off = float(s) - sec.s0, float(self.lane_offset_at(s))
        right = sum(float(lane.width(ds)) for lane in sec.right if lane.type != "none")
        left = sum(float(lane.width(ds)) for lane in sec.left if lane.type != "none")
        return off - right, off + left

    # -------------------------------------------------------------- projection

    def project(self, x: float, y: float) -> tuple[float, float]:
        """Nearest reference-line point: ``(s, t)`` [m] with t positive left."""
        s, t, _ = self.project_array(np.asarray([x], dtype=float), np.asarray([y], dtype=float))
        return float(s[0]), float(t[0])

    def project_array(self, x, y, n_candidates: int = 3):
        """Vectorised projection of points onto the reference line.

        Returns ``(s, t, d_long)`` arrays [m]: ``d_long`` is the residual along the road
        tangent, ~0 except for points beyond the road ends (where s is clamped).

        Robustness: a coarse sampled search (step <= 1 m and <= 0.1 rad of heading)
        yields up to ``n_candidates`` local minima of the sampled distance; each is
        refined by safeguarded Newton steps on (p - r(s))·T(s) = 0 inside its sample
        bracket, and the nearest refined point wins.
        """
        x = np.asarray(x, dtype=float)
        y = np.asarray(y, dtype=float)
        shape = np.broadcast(x, y).shape
        px, py = np.broadcast_to(x, shape).ravel(), np.broadcast_to(y, shape).ravel()
        s_out, t_out, f_out = np.empty(px.shape), np.empty(px.shape), np.empty(px.shape)
        for a in range(0, px.size, _PROJECT_CHUNK):
            sl = slice(a, a + _PROJECT_CHUNK)
            s_out[sl], t_out[sl], f_out[sl] = self._project_chunk(px[sl], py[sl], n_candidates)
        return s_out.reshape(shape), t_out.reshape(shape), f_out.reshape(shape)

    def _project_chunk(self, px: np.ndarray, py: np.ndarray, n_candidates: int):
        ss, xy = self._sample_s, self._sample_xy
        m = len(ss)
        # |p - q|² via one matrix product; round-off ~1e-16 |p|² only affects which coarse
        # samples become candidates (`kernel.matmul`: the same ones on every machine).
        p = np.stack([px, py], axis=1)
        d2 = (p * p).sum(1)[:, None] + (xy * xy).sum(1)[None, :] - 2.0 * matmul(p, xy.T)
        # Local minima of the sampled distance (ends included) are the candidate basins;
        # take the n_candidates nearest ones.
        d2_min = np.full_like(d2, np.inf)
        if m > 2:
            mid = d2[:, 1:-1]
            d2_min[:, 1:-1] = np.where((mid <= d2[:, :-2]) & (mid <= d2[:, 2:]), mid, np.inf)
        d2_min[:, 0] = np.where(d2[:, 0] <= d2[:, 1], d2[:, 0], np.inf)
        d2_min[:, -1] = np.where(d2[:, -1] <= d2[:, -2], d2[:, -1], np.inf)
        rows = np.arange(len(px))
        picks = []
        for _ in range(min(n_candidates, m)):
            j = np.argmin(d2_min, axis=1)
            picks.append(np.where(np.isfinite(d2_min[rows, j]), j, picks[0] if picks else j))
            d2_min[rows, j] = np.inf
        cand = np.stack(picks, axis=1)
        lo = ss[np.clip(cand - 1, 0, m - 1)]
        hi = ss[np.clip(cand + 1, 0, m - 1)]
        s = ss[cand]
        qx = np.broadcast_to(px[:, None], s.shape)
        qy = np.broadcast_to(py[:, None], s.shape)
        for _ in range(_NEWTON_ITERS):
            rx, ry, h = self.reference_pose(s)
            k = self.curvature(s)
            dx, dy = qx - rx, qy - ry
            c, sn = np.cos(h), np.sin(h)
            f = dx * c + dy * sn  # along-tangent residual; 0 at a perpendicular foot
            t = -dx * sn + dy * c
            denom = 1.0 - k * t  # d/ds of -f; <= 0 near/behind the centre of curvature
            step = np.where(denom > 0.05, f / np.maximum(denom, 0.05), 0.5 * f)
            s_new = np.clip(s + step, lo, hi)
            if np.all(np.abs(s_new - s) < 1e-12):
                s = s_new
                break
            s = s_new
        rx, ry, h = self.reference_pose(s)
        dx, dy = qx - rx, qy - ry
        c, sn = np.cos(h), np.sin(h)
        f = dx * c + dy * sn
        t = -dx * sn + dy * c
        best = np.argmin(dx * dx + dy * dy, axis=1)[:, None]
        pick = lambda a: np.take_along_axis(a, best, axis=1)[:, 0]  # noqa: E731
        s, t, f = pick(s), pick(t), pick(f)
        # Snap onto lane-section starts: lane ids change there, and a 1e-13 m round-off
        # must not decide which section (hence which lane id) a point belongs to.
        starts = self._section_starts
        near = np.clip(np.searchsorted(starts, s), 1, max(1, len(starts) - 1))
        for cand in (near - 1, np.minimum(near, len(starts) - 1)):
            snap = np.abs(s - starts[cand]) < _SECTION_SNAP_M
            s = np.where(snap, starts[cand], s)
        return s, t, f

    def lane_offset(self, lane_id: int, x, y):
        """Signed lateral distance [m] of point(s) from the centre line of ``lane_id``
        (positive = left of the lane centre, looking along +s).

        Points are projected onto the reference line first; the result is NaN where the
        lane does not exist at the projected s.
        """
        scalar = np.ndim(x) == 0 and np.ndim(y) == 0
        s, t, _ = self.project_array(x, y)
        inner, outer = self._lane_t(lane_id, s, rates=False)
        off = t - 0.5 * (inner + outer)
        return float(off) if scalar else off

    def speed_limit(self, s: float) -> float | None:
        """The map's speed limit [m/s] at station `s` [m] (None where it gives none)."""
        limit = None
        for start, value in self.speed_limits:
            if start <= s + 1e-9:
                limit = value
        return limit

    @property
    def is_junction_road(self) -> bool:
        return self.junction not in ("", "-1")
