"""The bev stack's per-step kernels: the tracks in road coordinates (`bev._road_frame`, the
unhinted projection through bounding boxes `fastroad.project_boxed`) and the controller's
steering law (`control._steer`). Each compiled kernel gives its Python's bits, and both give
the bits of the code they replaced (kept below verbatim as the oracle: `_old_road_frame`,
`_OldController`), non-finite values included; where that code raised, they raise."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from addt_dsl.kernel import bits, interpreted
from addt_dsl.plan import SegmentPlan
from addt_dsl.runtime.fastroad import _project, project_boxed
from addt_dsl.stack.bev import CROSSING_MIN_SPEED, CROSSING_SIN, SET_OFF_ACCEL, road_frame_objects
from addt_dsl.stack.control import Controller
from addt_dsl.stack.nodes import EgoBody, LatticePlanner, Obj, Plan, Tracker
from tests.unit.stack.roadkit import HAIRPIN, STRAIGHT
from tests.unit.stack.roadkit import road as _road

ROADS = (STRAIGHT, HAIRPIN)

coords = st.floats(-150.0, 350.0)
odd = st.sampled_from([math.nan, math.inf, -math.inf, 0.0, -0.0, 1e300])
values = st.one_of(st.floats(-40.0, 40.0), odd)


# ---------------------------------------------------------------- the old code (oracles)

def _old_road_frame(road, tracked, t0):
    """`BevStack._run_planner`'s loop over the tracks before the kernel, verbatim."""
    objs = []
    for o in tracked:
        so, to = road.project(o.x, o.y)
        hdg = float(road.reference_pose(so)[2])
        c, s = math.cos(hdg), math.sin(hdg)
        rc, rs = abs(math.cos(o.heading - hdg)), abs(math.sin(o.heading - hdg))
        v_t = o.vy * c - o.vx * s
        a_s, a_t = o.ax * c + o.ay * s, o.ay * c - o.ax * s
        turned = rs
        if o.kind == "pedestrian" and math.hypot(o.vx, o.vy) > CROSSING_MIN_SPEED:
            turned = abs(math.sin(math.atan2(o.vy, o.vx) - hdg))
        if not (turned > CROSSING_SIN and abs(v_t) > CROSSING_MIN_SPEED):
            v_t = a_t = 0.0
            if o.kind == "cyclist" and turned > CROSSING_SIN and math.hypot(o.vx, o.vy) < CROSSING_MIN_SPEED:
                a_t = math.copysign(SET_OFF_ACCEL, float(t0 - to))
        objs.append((float(so), float(to), o.vx * c + o.vy * s, v_t,
                     o.length * rc + o.width * rs, o.length * rs + o.width * rc, a_s, a_t))
    return objs


class _OldController(Controller):
    """`Controller.command`'s steering before the kernel, verbatim (to its fault site)."""

    @staticmethod
    def _path(plan, s):
        length = plan.lateral_length_m
        u = min(1.0, max(0.0, (s - plan.s_start) / length))
        d = plan.t_target - plan.t_start
        if u <= 0.0 or u >= 1.0:
            return plan.t_start + d * u, 0.0, 0.0
        return (plan.t_start + d * u * u * (3 - 2 * u), d * 6.0 * u * (1.0 - u) / length,
                d * (6.0 - 12.0 * u) / (length * length))

    def _course(self, x, y, heading, dt, speed):
        course = heading
        if self._last_xy is not None:
            dx, dy = x - self._last_xy[0], y - self._last_xy[1]
            if dx * dx + dy * dy > (0.3 * max(speed, 1.0) * dt) ** 2 and speed > 1.0:
                course = heading + math.remainder(math.atan2(dy, dx) - heading, math.tau)
        self._last_xy = (x, y)
        return course

    def steer(self, plan, ego, road, s_now, t_now, dt):
        x, y, heading, speed = ego
        course = self._course(x, y, heading, dt, speed)
        t_path, slope, _ = self._path(plan, s_now)
        _, _, road_heading = road.reference_pose(s_now)
        e_lat = t_now - t_path
        e_course = math.remainder(course - road_heading - math.atan(slope), math.tau)
        s_pre = min(s_now + speed * self.preview_s, road.length)
        t_pre, _, bend = self._path(plan, s_pre)
        kappa_road = float(road.curvature(s_pre))
        kappa = kappa_road / max(0.2, 1.0 - kappa_road * t_pre) + bend
        steer = self.wheelbase * kappa + self.understeer * speed * speed * kappa
        v = max(speed, 5.0)
        wn, zeta = self.lateral_wn, self.lateral_zeta
        steer -= self.wheelbase * (wn * wn * e_lat / (v * v) + 2.0 * zeta * wn * e_course / v)
        return max(-self.max_steer, min(self.max_steer, steer))


class _OldTracker(Tracker):
    """`Tracker.update` before the kernel, verbatim (with its `_predict_cov` and `_correct`)."""

    def update(self, objs: list[Obj], stamp_s: float, corrupt) -> None:
        predicted = [self._predict(o, stamp_s - ts) for o, ts, _ in self.tracks]
        new_tracks = []
        used = set()
        r_p = self.position_noise_m ** 2
        for det in objs:
            best, best_d = None, math.inf
            for i, (p, (_, ts, _)) in enumerate(zip(predicted, self.tracks)):
                if i in used:
                    continue
                d = math.hypot(p.x - det.x, p.y - det.y)
                if math.isnan(p.vx):
                    v_max = self.class_max_speed.get(det.kind, self.max_speed)
                    gate = self.gate_m + v_max * (stamp_s - ts)
                else:
                    gate = self.gate_m
                if d < gate and d < best_d:
                    best, best_d = i, d
            measured_v = not math.isnan(det.vx)
            if best is None:
                # A new track: the detection, with its velocity if the detector gives one.
                cov = (r_p, 0.0, self.velocity_noise_mps ** 2 if measured_v else math.inf)
                new_tracks.append((det, stamp_s, cov))
                continue
            used.add(best)
            prev, ts, cov = self.tracks[best]
            dt = max(stamp_s - ts, 1e-3)
            if math.isnan(prev.vx) and not measured_v:
                # Second sighting without a velocity: two-point start.
                x, y = det.x, det.y
                vx, vy = (det.x - prev.x) / dt, (det.y - prev.y) / dt
                cov = (r_p, r_p / dt, 2.0 * r_p / dt ** 2)
            else:
                if math.isnan(prev.vx):  # a velocity-less track meets a detector's velocity
                    pred, cov = prev, (cov[0], 0.0, math.inf)
                else:
                    pred = predicted[best]
                    cov = self._predict_cov(cov, dt, self.accel_noise.get(det.kind, self.default_accel_noise))
                (x, vx), (y, vy), cov = self._correct(
                    (pred.x, 0.0 if math.isnan(pred.vx) else pred.vx),
                    (pred.y, 0.0 if math.isnan(pred.vy) else pred.vy), cov, (det.x, det.y),
                    (det.vx, det.vy) if measured_v else None)
            ax = ay = 0.0
            if measured_v and not math.isnan(prev.vx):
                g = self.accel_gain
                ax = prev.ax + g * ((vx - prev.vx) / dt - prev.ax)
                ay = prev.ay + g * ((vy - prev.vy) / dt - prev.ay)
            # A second sighting in a row confirms a weak track (2 of 2).
            est = Obj(x, y, det.heading, corrupt("tracker.vx", vx), vy, det.length, det.width,
                      kind=det.kind, weak=det.weak and prev.weak and stamp_s - ts > self.confirm_s, ax=ax, ay=ay)
            new_tracks.append((est, stamp_s, cov))
        # Keep unmatched tracks alive (coasting) so a dropped frame does not erase an object.
        for i, (p, ts, cov) in enumerate(self.tracks):
            if i not in used and stamp_s - ts <= self.max_age_s:
                new_tracks.append((p, ts, cov))
        self.tracks = new_tracks

    @staticmethod
    def _predict_cov(cov, dt: float, accel_std: float) -> tuple[float, float, float]:
        """P <- F P F' + Q for F = [[1, dt], [0, 1]], Q of white acceleration `accel_std`."""
        pp, pv, vv = cov
        q = accel_std ** 2
        return (pp + 2.0 * dt * pv + dt * dt * vv + q * dt ** 4 / 4.0,
                pv + dt * vv + q * dt ** 3 / 2.0,
                vv + q * dt * dt)

    def _correct(self, state_x, state_y, cov, z_pos, z_vel):
        """Kalman update of both axes' (p, v) with the position, then the velocity if measured
        (independent measurements: one after the other is the joint update)."""
        pp, pv, vv = cov
        r_p = self.position_noise_m ** 2
        if math.isinf(vv):  # no velocity known yet: the position resets p, v stays unknown
            k_p, k_v = 1.0, 0.0
            pp, pv = r_p, 0.0
        else:
            s = pp + r_p
            k_p, k_v = pp / s, pv / s
            pp, pv, vv = pp - k_p * pp, pv - k_p * pv, vv - k_v * pv
        (px, vx), (py, vy) = state_x, state_y
        px, vx = px + k_p * (z_pos[0] - px), vx + k_v * (z_pos[0] - px)
        py, vy = py + k_p * (z_pos[1] - py), vy + k_v * (z_pos[1] - py)
        if z_vel is not None:
            r_v = self.velocity_noise_mps ** 2
            if math.isinf(vv):
                k_p, k_v = 0.0, 1.0
                vv = r_v
            else:
                s = vv + r_v
                k_p, k_v = pv / s, vv / s
                pp, pv, vv = pp - k_p * pv, pv - k_p * vv, vv - k_v * vv
            px, vx = px + k_p * (z_vel[0] - vx), vx + k_v * (z_vel[0] - vx)
            py, vy = py + k_p * (z_vel[1] - vy), vy + k_v * (z_vel[1] - vy)
        return (px, vx), (py, vy), (pp, pv, vv)



def _lateral_path(s: np.ndarray, s_start: float, t_start: float, t_target: float,
                  length: float) -> tuple[np.ndarray, np.ndarray]:
    """The planned lateral offset t(s) [m] and its d2t/ds2 [1/m] at stations `s` [m]: the
    smoothstep `Controller` steers by (`_smoothstep_path`: per control step, on floats)."""
    u = np.clip((s - s_start) / length, 0.0, 1.0)
    d = t_target - t_start
    inside = (u > 0.0) & (u < 1.0)
    return t_start + d * u * u * (3.0 - 2.0 * u), np.where(inside, d * (6.0 - 12.0 * u) / (length * length), 0.0)


class _OldPlanner(LatticePlanner):
    """`LatticePlanner._curve_speed` before the kernel, verbatim (with `_lateral_path`)."""

    def _curve_speed(self, road, s0: float, t0: float, ego_speed: float, speed: float,
                     lateral: tuple[float, float, float, float] | None = None) -> tuple[float, float]:
        """(speed cap [m/s], braking [m/s^2]) for the curves ahead (a junction's corner, a
        bend, a lane change): the fastest speed now from which slowing at `curve_decel` keeps
        the lateral acceleration on the path ahead under `max_lateral_accel` (v^2 <= a_lat /
        kappa + 2 * decel * distance, over the stopping preview), and, once the ego is at or
        past that envelope, the deceleration that reaches each bend's speed at the bend (like
        a stop line's: the speed loop alone lags by a couple of m/s). `lateral` = (s_start,
        t_start, t_target, length) [m] of the lateral manoeuvre the ego follows: the path's
        curvature is the road's at the manoeuvre's offset plus the manoeuvre's own, as the
        controller steers it (a lane change in a bend curves more than either)."""
        reach = min(self.curve_preview_max_m, speed * speed / (2.0 * self.curve_decel) + 2.0 * self.body.length_m)
        dist, kappa = road.curvature_ahead(s0, reach)
        if lateral is None or (s0 - lateral[0]) >= lateral[3] or lateral[2] == lateral[1]:
            # The curvature of the line the ego drives, offset t0 from the sampled one.
            lane_kappa = np.abs(kappa) / np.maximum(1.0 - kappa * t0, 0.1)
        else:
            t_path, bend = _lateral_path(s0 + dist, *lateral)
            lane_kappa = np.abs(kappa / np.maximum(1.0 - kappa * t_path, 0.2) + bend)
        bends = lane_kappa > 1e-6
        if not bends.any():
            return math.inf, 0.0
        bend_v2, d = self.max_lateral_accel / lane_kappa[bends], dist[bends]
        cap = float(np.sqrt(np.min(bend_v2 + 2.0 * self.curve_decel * d)))
        if ego_speed <= cap:
            return cap, 0.0
        needed = float(np.max((ego_speed * ego_speed - bend_v2) / (2.0 * np.maximum(d, 1.0))))
        return cap, min(self.max_brake, needed) if needed > 0.0 else 0.0


def _outcome(fn):
    """The result's bits, or the exception's type and words."""
    try:
        out = fn()
    except (ValueError, ZeroDivisionError, OverflowError) as e:
        return type(e).__name__, str(e)
    return bits(out)


# ---------------------------------------------------------------- projection

@settings(max_examples=60, deadline=None)
@given(st.sampled_from(ROADS), st.one_of(coords, odd), st.one_of(coords, odd))
def test_the_boxed_projection_gives_the_full_searchs_bits(road, x, y):
    args = (road._tab, road._ds, road._last_i, road.length)
    want = _outcome(lambda: _project(*args, x, y, 0.0, False))
    assert _outcome(lambda: project_boxed(*args, road.boxes(), x, y)) == want
    with interpreted():
        assert _outcome(lambda: project_boxed(*args, road.boxes(), x, y)) == want


def test_the_boxed_projection_finds_the_nearer_straight_of_a_hairpin():
    # 100 m apart (the arc's diameter): 30 m from the outbound straight, 70 m from the return.
    s, t = project_boxed(HAIRPIN._tab, HAIRPIN._ds, HAIRPIN._last_i, HAIRPIN.length, HAIRPIN.boxes(), 120.0, 30.0)
    assert s == pytest.approx(120.0) and t == pytest.approx(30.0)
    s, t = project_boxed(HAIRPIN._tab, HAIRPIN._ds, HAIRPIN._last_i, HAIRPIN.length, HAIRPIN.boxes(), 120.0, 70.0)
    assert s == pytest.approx(200.0 + 50.0 * math.pi + 80.0) and t == pytest.approx(30.0)  # left of it, driving back
    # on the straight road: a point 2 m left of station 100
    assert STRAIGHT.project(100.0, 2.0) == road_frame_objects(STRAIGHT, [Obj(100.0, 2.0, 0.0, 5.0, 0.0, 4.0, 2.0)],
                                                              0.0)[0][:2]


# ---------------------------------------------------------------- tracks in road coordinates

tracks = st.lists(st.builds(lambda x, y, h, vx, vy, ax, ay, length, width, kind:
                            Obj(x, y, h, vx, vy, length, width, kind=kind, ax=ax, ay=ay),
                            coords, coords, st.one_of(st.floats(-7.0, 7.0), odd), values, values, values, values,
                            st.floats(0.3, 12.0), st.floats(0.3, 3.0),
                            st.sampled_from(["car", "pedestrian", "cyclist", ""])),
                  min_size=1, max_size=6)


@settings(max_examples=80, deadline=None)
@given(st.sampled_from(ROADS), tracks, st.floats(-8.0, 8.0))
def test_the_tracks_in_road_coordinates_give_the_old_loops_bits(road, tracked, t0):
    want = _outcome(lambda: _old_road_frame(road, tracked, t0))
    assert _outcome(lambda: road_frame_objects(road, tracked, t0)) == want
    with interpreted():
        assert _outcome(lambda: road_frame_objects(road, tracked, t0)) == want


def test_a_pedestrian_crossing_a_straight_road_keeps_its_velocity_across():
    walker = Obj(50.0, -3.0, 0.0, 0.0, 1.5, 0.6, 0.6, kind="pedestrian")  # box along the road, walking across
    car = Obj(80.0, -1.0, 0.0, 10.0, 0.3, 4.5, 1.8, kind="car")
    (s, t, v_s, v_t, along, across, _, _), car_sc = road_frame_objects(STRAIGHT, [walker, car], -1.75)
    assert (s, t, v_s, v_t, along, across) == (50.0, -3.0, 0.0, 1.5, 0.6, 0.6)
    assert car_sc[2:4] == (10.0, 0.0)  # aligned with the road: its lateral velocity is noise


# ---------------------------------------------------------------- steering

plans = st.builds(lambda s_start, t_start, t_target, length: Plan(-1, t_target, 20.0, s_start, t_start, length, 0.0),
                  st.floats(0.0, 400.0), st.floats(-6.0, 6.0), st.floats(-6.0, 6.0),
                  st.one_of(st.floats(0.5, 120.0), st.sampled_from([0.0, -0.0, 1e-200, math.nan, math.inf])))


@settings(max_examples=100, deadline=None)
@given(st.sampled_from(ROADS), plans, coords, coords, st.one_of(st.floats(-4.0, 4.0), odd),
       st.one_of(st.floats(0.0, 40.0), odd), st.one_of(st.none(), st.tuples(coords, coords)),
       st.floats(0.0, 500.0), st.floats(-6.0, 6.0), st.one_of(st.floats(0.0, 3.0), odd))
def test_the_steering_kernel_gives_the_old_laws_bits(road, plan, x, y, heading, speed, last, s_now, t_now, wn):
    old = _OldController({}, 2.7)
    old.lateral_wn, old._last_xy = wn, last
    want = _outcome(lambda: old.steer(plan, (x, y, heading, speed), road, s_now, t_now, 0.01))

    def steer():
        """The value the steering's fault site sees (or the raise, before that site)."""
        c = Controller({}, 2.7)
        c.lateral_wn, c.last_xy = wn, last
        sites = {}

        def record(site, value):
            sites[site] = value
            return value

        out = _outcome(lambda: c.command(plan, (x, y, heading, speed), road, s_now, t_now, 0.01, record))
        assert c.last_xy == (x, y)
        return out if isinstance(out, tuple) else bits(sites["control.steer"])

    assert steer() == want
    with interpreted():
        assert steer() == want


def test_on_its_path_on_a_straight_road_it_steers_straight_and_the_sites_come_in_order():
    sites = []

    def record(site, value):
        sites.append(site)
        return value

    c = Controller({}, 2.7)
    plan = Plan(-1, -1.75, 20.0, 0.0, -1.75, 60.0, 0.0)
    steer, _ = c.command(plan, (100.0, -1.75, 0.0, 20.0), STRAIGHT, 100.0, -1.75, 0.01, record)
    assert steer == 0.0
    assert sites == ["control.kp", "control.ki", "control.kd", "control.lateral_wn", "control.understeer",
                     "control.steer", "control.integral", "control.accel"]
    # 1 m right of the path (a first cycle: no course from poses yet): steers left, by the
    # feedback's wheelbase * wn^2 e / v^2 term (course error 0)
    steer, _ = Controller({}, 2.7).command(plan, (100.0, -2.75, 0.0, 20.0), STRAIGHT, 100.0, -2.75, 0.01, record)
    assert steer == pytest.approx(2.7 * 1.0 / 400.0)


# ---------------------------------------------------------------- tracking

def _tracker(cls, tracks, position_noise, velocity_noise):
    t = cls(1.0, position_noise, velocity_noise)
    t.tracks = [(Obj(o.x, o.y, o.heading, o.vx, o.vy, o.length, o.width, kind=o.kind, weak=o.weak, ax=o.ax,
                     ay=o.ay), ts, cov) for o, ts, cov in tracks]
    return t


def _state(tracker):
    return [(o.x, o.y, o.heading, o.vx, o.vy, o.length, o.width, o.kind, o.weak, o.ax, o.ay, ts, *cov)
            for o, ts, cov in tracker.tracks]


near = st.floats(-12.0, 12.0)
velocity = st.one_of(st.floats(-15.0, 15.0), st.just(math.nan), odd)
objects = st.builds(lambda x, y, vx, vy, kind, weak, ax: Obj(x, y, 0.3, vx, vy, 4.0, 1.8, kind=kind, weak=weak,
                                                             ax=ax, ay=-ax),
                    near, near, velocity, velocity, st.sampled_from(["car", "pedestrian", "cyclist", "obstacle"]),
                    st.booleans(), st.floats(-3.0, 3.0))
covariances = st.one_of(st.tuples(st.floats(1e-4, 2.0), st.floats(-0.5, 0.5), st.floats(1e-4, 4.0)),
                        st.tuples(st.floats(1e-4, 2.0), st.just(0.0), st.just(math.inf)),
                        st.tuples(st.sampled_from([-0.01, -1e-6, 0.0]), st.floats(-1.0, 1.0), odd))
stamps = st.one_of(st.floats(-1.0, 1.0), st.sampled_from([-1e160, 1e-9, math.nan]))


@settings(max_examples=150, deadline=None)
@given(st.lists(st.tuples(objects, stamps, covariances), max_size=6), st.lists(objects, max_size=6),
       st.one_of(st.none(), st.floats(1e-4, 0.5)), st.one_of(st.none(), st.floats(1e-4, 0.5)))
def test_the_tracker_kernel_gives_the_old_updates_bits(tracks, dets, position_noise, velocity_noise):
    """Tracks of all kinds (velocity unknown, covariance corrupted: a memory fault's), the
    detector measuring velocities or not: the same tracks, the same values through the
    fault site in the same order, the same raise (at the same detection)."""
    def run(cls):
        tracker = _tracker(cls, tracks, position_noise, velocity_noise)
        seen = []

        def site(name, value):
            seen.append((name, value))
            return value + 1.0  # a corruption: it must land in the track as before

        out = _outcome(lambda: tracker.update(dets, 0.1, site))
        return out if isinstance(out, tuple) else bits([v for r in _state(tracker) for v in r
                                                        if not isinstance(v, str)]), bits([v for _, v in seen])

    want = run(_OldTracker)
    assert run(Tracker) == want
    with interpreted():
        assert run(Tracker) == want


def test_a_detection_two_metres_from_a_track_updates_it_and_a_far_one_starts_another():
    tracker = Tracker(1.0, 0.1, 0.1)
    tracker.update([Obj(10.0, 0.0, 0.0, 5.0, 0.0, 4.0, 1.8, kind="car")], 0.0, lambda site, v: v)
    tracker.update([Obj(12.0, 0.0, 0.0, 5.0, 0.0, 4.0, 1.8, kind="car"),
                    Obj(30.0, 0.0, 0.0, 5.0, 0.0, 4.0, 1.8, kind="car")], 0.1, lambda site, v: v)
    (first, ts, cov), (second, _, _) = tracker.tracks
    # predicted to 10.5 m, measured at 12 m: the filter lands in between
    assert 10.5 < first.x < 12.0 and ts == 0.1 and cov[0] < 0.1 ** 2
    assert second.x == 30.0 and len(tracker.tracks) == 2


# ---------------------------------------------------------------- curve speed

CURVY = _road(SegmentPlan(kind="line", length_m=60.0), SegmentPlan(kind="arc", length_m=40.0, curvature_per_m=0.05),
              SegmentPlan(kind="spiral", length_m=50.0, curv_start_per_m=-0.02, curv_end_per_m=0.03),
              SegmentPlan(kind="line", length_m=100.0))
laterals = st.one_of(st.none(), st.tuples(st.floats(-20.0, 200.0), st.floats(-5.0, 5.0), st.floats(-5.0, 5.0),
                                          st.one_of(st.floats(0.5, 90.0), st.sampled_from([0.0, 1e-200, math.nan]))))


@settings(max_examples=120, deadline=None)
@given(st.sampled_from((STRAIGHT, HAIRPIN, CURVY)), st.floats(0.0, 250.0), st.one_of(st.floats(-8.0, 25.0), odd),
       st.one_of(st.floats(0.0, 40.0), st.just(math.nan)), st.floats(0.0, 40.0), laterals,
       st.one_of(st.floats(0.5, 6.0), st.sampled_from([0.0, math.nan])))
def test_the_curve_envelope_kernel_gives_the_old_curve_speeds_bits(road, s0, t0, ego_speed, speed, lateral, a_lat):
    settings_ = {"max_lateral_accel": a_lat}
    old, new = _OldPlanner(settings_, EgoBody()), LatticePlanner(settings_, EgoBody())
    with np.errstate(all="ignore"):
        want = _outcome(lambda: old._curve_speed(road, s0, t0, ego_speed, speed, lateral))
    assert _outcome(lambda: new._curve_speed(road, s0, t0, ego_speed, speed, lateral)) == want
    with interpreted():
        assert _outcome(lambda: new._curve_speed(road, s0, t0, ego_speed, speed, lateral)) == want


def test_on_a_bend_of_known_radius_the_cap_is_the_lateral_limit_plus_the_slowing():
    # 20 m radius from 60 m on: at 50 m the cap is sqrt(a_lat * r + 2 * decel * 10 m)
    planner = LatticePlanner({"max_lateral_accel": 4.0}, EgoBody())
    cap, brake = planner._curve_speed(CURVY, 50.0, 0.0, 5.0, 20.0)
    assert cap == pytest.approx(math.sqrt(4.0 * 20.0 + 2.0 * 2.0 * 10.0), rel=1e-3) and brake == 0.0
    assert planner._curve_speed(STRAIGHT, 50.0, 0.0, 30.0, 30.0) == (math.inf, 0.0)


# ---------------------------------------------------------------- ground-truth perception

def _old_sensed(gx, gy, ego, actual, nominal):
    """`GroundTruthPerception.run`'s position of one object before its kernel, verbatim
    (numpy rows and two `kernel.matmul` products)."""
    from addt_dsl.kernel import matmul
    from addt_dsl.runtime.sensors import rotation

    x, y, heading = ego
    cos_h, sin_h = math.cos(heading), math.sin(heading)
    rot_a, rot_n = rotation(*actual[3:]), rotation(*nominal[3:])
    dx, dy = gx - x, gy - y
    pv = np.array([cos_h * dx + sin_h * dy, -sin_h * dx + cos_h * dy, 0.8])
    ps = matmul(rot_a.T, pv - np.array(actual[:3]))
    pn = matmul(rot_n, ps) + np.array(nominal[:3])
    return float(pn[0]), float(pn[1])


mounts = st.tuples(st.floats(-3.0, 3.0), st.floats(-1.5, 1.5), st.floats(0.0, 2.5), st.floats(-0.2, 0.2),
                   st.floats(-0.2, 0.2), st.floats(-math.pi, math.pi))


@settings(max_examples=150, deadline=None)
@given(st.lists(st.tuples(st.floats(-500.0, 500.0), st.floats(-500.0, 500.0)), min_size=1, max_size=6),
       st.tuples(st.floats(-500.0, 500.0), st.floats(-500.0, 500.0), st.floats(-7.0, 7.0)), mounts, mounts)
def test_the_ground_truth_positions_kernel_gives_the_two_products_bits(objects, ego, actual, nominal):
    from addt_dsl.runtime.sensors import rotation
    from addt_dsl.stack.nodes import _sensed_positions

    want = [bits(_old_sensed(gx, gy, ego, actual, nominal)) for gx, gy in objects]
    x, y, heading = ego

    def got():
        out = np.empty((len(objects), 2))
        _sensed_positions(np.array(objects, dtype=float), x, y, math.cos(heading), math.sin(heading),
                          rotation(*actual[3:]), rotation(*nominal[3:]), np.array(actual[:3]), np.array(nominal[:3]),
                          out)
        return [bits(row) for row in out.tolist()]

    assert got() == want
    with interpreted():
        assert got() == want


@settings(max_examples=80, deadline=None)
@given(st.lists(st.integers(-3, 40), max_size=120), st.sampled_from([np.int64, np.int32]))
def test_hit_counts_are_numpys_unique_with_counts(values, dtype):
    """`nodes.hit_counts`: the ids ascending and their counts as `np.unique(..., return_counts=True)`
    gives them, compiled and interpreted (empty frames, negative ids, int32 included)."""
    from addt_dsl.stack.nodes import hit_counts

    hits = np.array(values, dtype=dtype)
    ids, counts = np.unique(hits, return_counts=True)
    want = (ids.tolist(), counts.tolist())
    assert hit_counts(hits) == want
    with interpreted():
        assert hit_counts(hits) == want
