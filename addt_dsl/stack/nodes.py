"""The default AD stack's nodes: perception, tracking, lattice planning, control.

Each node is a small class with a rate, a latency model and named fault sites; the
stack (`addt_dsl.stack.bev`) wires them on the bus. Values flowing through a fault
site pass through `sites(name, value)`, where the fault schedule may corrupt them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from addt_dsl.vehicles import CAR


@dataclass
class Obj:
    """A perceived or tracked object in world coordinates [m, rad, m/s]."""

    x: float
    y: float
    heading: float
    vx: float
    vy: float
    length: float
    width: float
    confidence: float = 1.0
    s: float = 0.0
    t: float = 0.0


# ---------------------------------------------------------------- perception

class GroundTruthPerception:
    """Objects hit by at least `min_hits` lidar returns, positions from ground truth + noise.

    Positions are computed where the *actual* (possibly shifted) sensor sees them and
    mapped back with the *nominal* extrinsics, so a misaligned mount produces the
    distance-dependent errors a real stack shows.
    """

    name = "perception"
    sites = ("perception.x", "perception.y", "perception.count")

    def __init__(self, settings: dict, rng: np.random.Generator):
        self.noise_m = float(settings.get("perception_noise", 0.1))
        self.min_hits = int(settings.get("min_hits", 2))
        self.rng = rng

    def run(self, frame, world, sensor, ego_pose, corrupt) -> list[Obj]:
        from addt_dsl.runtime.sensors import rotation

        hits = frame.data["hit_body"]
        if len(hits) == 0:
            return []
        ids, counts = np.unique(hits, return_counts=True)
        x, y, heading, _ = ego_pose
        cos_h, sin_h = math.cos(heading), math.sin(heading)
        actual, nominal = sensor.actual, sensor.nominal
        rot_a = rotation(actual.roll, actual.pitch, actual.yaw)
        rot_n = rotation(nominal.roll, nominal.pitch, nominal.yaw)
        objs = []
        for body, count in zip(ids.tolist(), counts.tolist()):
            if count < self.min_hits:
                continue
            gt = world.actor_by_body(body)
            if gt is None:
                continue
            # World → vehicle frame → actual sensor frame → vehicle frame via nominal calibration.
            dx, dy = gt.x - x, gt.y - y
            pv = np.array([cos_h * dx + sin_h * dy, -sin_h * dx + cos_h * dy, 0.8])
            ps = rot_a.T @ (pv - np.array([actual.x, actual.y, actual.z]))
            pn = rot_n @ ps + np.array([nominal.x, nominal.y, nominal.z])
            yaw_err = (actual.yaw - nominal.yaw)
            vx_w = gt.speed * math.cos(gt.heading)
            vy_w = gt.speed * math.sin(gt.heading)
            px = float(pn[0]) + self.rng.normal(0.0, self.noise_m)
            py = float(pn[1]) + self.rng.normal(0.0, self.noise_m)
            px = corrupt("perception.x", px)
            py = corrupt("perception.y", py)
            wx = x + cos_h * px - sin_h * py
            wy = y + sin_h * px + cos_h * py
            objs.append(Obj(wx, wy, gt.heading - yaw_err, vx_w, vy_w, gt.length_m, gt.width_m))
        # The detection count bounds the list the downstream nodes read: a corrupted count
        # hides objects (a NaN or infinite count raises, which the loop records as detected).
        count = int(corrupt("perception.count", float(len(objs))))
        return objs[:max(0, count)]


# ---------------------------------------------------------------- tracking

class Tracker:
    """Nearest-neighbour association with constant-velocity prediction between frames.

    A detector that measures no velocity (learned perception: `vx = vy = nan`) gets one
    from the tracker: a track's second sighting initialises it from the displacement
    (gated by a maximum speed, since the first prediction has no velocity), later
    sightings smooth the displacement velocity with `velocity_gain`.
    """

    name = "tracker"
    sites = ("tracker.vx",)
    gate_m = 4.0
    max_age_s = 1.0
    velocity_gain = 0.35
    max_speed = 45.0  # [m/s] gate for a track whose velocity is not yet known

    def __init__(self, max_age_s: float = 1.0):
        self.max_age_s = max_age_s
        self.tracks: list[tuple[Obj, float]] = []  # (object, last update time)

    def update(self, objs: list[Obj], stamp_s: float, corrupt) -> None:
        predicted = [(self._predict(o, stamp_s - ts), ts) for o, ts in self.tracks]
        new_tracks = []
        used = set()
        for det in objs:
            best, best_d = None, math.inf
            for i, (p, ts) in enumerate(predicted):
                if i in used:
                    continue
                d = math.hypot(p.x - det.x, p.y - det.y)
                gate = self.gate_m if not math.isnan(p.vx) else self.gate_m + self.max_speed * (stamp_s - ts)
                if d < gate and d < best_d:
                    best, best_d = i, d
            if best is not None:
                used.add(best)
                prev, ts = self.tracks[best]
                dt = max(stamp_s - ts, 1e-3)
                mvx, mvy = (det.x - prev.x) / dt, (det.y - prev.y) / dt
                if not math.isnan(det.vx):
                    # Blend measured displacement with the detector's velocity estimate.
                    vx, vy = 0.5 * det.vx + 0.5 * mvx, 0.5 * det.vy + 0.5 * mvy
                elif math.isnan(prev.vx):
                    vx, vy = mvx, mvy
                else:
                    vx = prev.vx + self.velocity_gain * (mvx - prev.vx)
                    vy = prev.vy + self.velocity_gain * (mvy - prev.vy)
                det = Obj(det.x, det.y, det.heading, corrupt("tracker.vx", vx), vy, det.length, det.width)
            new_tracks.append((det, stamp_s))
        # Keep unmatched tracks alive (coasting) so a dropped frame does not erase an object.
        for i, (p, ts) in enumerate(self.tracks):
            if i not in used and stamp_s - ts <= self.max_age_s:
                new_tracks.append((p, ts))
        self.tracks = new_tracks

    @staticmethod
    def _predict(o: Obj, dt: float) -> Obj:
        if math.isnan(o.vx):  # velocity not measured yet: stays where it was seen
            return o
        return Obj(o.x + o.vx * dt, o.y + o.vy * dt, o.heading, o.vx, o.vy, o.length, o.width)

    def objects_at(self, time_s: float) -> list[Obj]:
        """Predicted tracks; one whose velocity is not known yet is reported as standing still."""
        out = []
        for o, ts in self.tracks:
            if time_s - ts <= self.max_age_s:
                p = self._predict(o, time_s - ts)
                out.append(p if not math.isnan(p.vx) else
                           Obj(p.x, p.y, p.heading, 0.0, 0.0, p.length, p.width, p.confidence))
        return out


# ---------------------------------------------------------------- planning

@dataclass
class Plan:
    """Planner output: a target lateral offset path on the ego road and a target speed."""

    lane: int
    t_target: float
    speed: float
    s_start: float
    t_start: float
    lateral_length_m: float
    stamp_s: float


class LatticePlanner:
    """Lane-keep / lane-change candidates × speed profiles, costed and collision-checked.

    Candidates are evaluated against constant-velocity predictions of the tracked
    objects in road coordinates over a fixed horizon; the cheapest collision-free one
    wins. Costs: progress (speed deficit), comfort (lane changes, braking), clearance,
    and a keep-right preference so the ego returns after an overtake.
    """

    name = "planner"
    sites = ("planner.speed", "planner.t_target", "planner.t_start", "planner.path_length", "planner.cost")
    horizon_s = 5.0
    dt_s = 0.5

    def __init__(self, settings: dict):
        self.cruise = float(settings.get("cruise_speed", 25.0))
        self.time_gap = float(settings.get("time_gap", 1.5))
        self.current_lane: int | None = None
        self.maneuver: tuple[int, float, float, float] | None = None
        self.lane_change_cooldown_s = 0.0
        self.last_change_s = -1e9

    def plan(self, ego_sc, ego_speed, objs_sc, road, road_id, stamp_s, corrupt) -> Plan:
        s0, t0, lane0 = ego_sc
        if self.current_lane is None:
            self.current_lane = lane0
        lanes = road.driving_lane_ids(s0)
        current = self.current_lane
        candidates_lanes = [l for l in lanes if abs(l - current) <= 1 and _same_side(l, current)]
        best = None
        for lane in candidates_lanes:
            t_lane = float(road.lane_center_t(lane, s0))
            for speed in self._speeds(ego_speed):
                cost = corrupt("planner.cost",
                               self._cost(lane, t_lane, speed, s0, t0, ego_speed, objs_sc, current, lanes, stamp_s))
                if best is None or cost < best[0]:
                    best = (cost, lane, t_lane, speed)
        _, lane, t_lane, speed = best
        if lane != current:
            self.last_change_s = stamp_s
            self.current_lane = lane
        speed = corrupt("planner.speed", speed)
        t_lane = corrupt("planner.t_target", t_lane)
        # The lateral manoeuvre keeps its start while its target lane stays the same, so
        # replanning does not restart the profile (which would flatten it every cycle).
        if self.maneuver is None or self.maneuver[0] != lane:
            self.maneuver = (lane, s0, t0, max(30.0, 3.0 * ego_speed))
        _, s_start, t_start, lateral_len = self.maneuver
        # The published trajectory: lateral path from (s_start, t_start) to t_target over path_length.
        t_start = corrupt("planner.t_start", t_start)
        lateral_len = corrupt("planner.path_length", lateral_len)
        return Plan(lane, t_lane, speed, s_start, t_start, lateral_len, stamp_s)

    def _speeds(self, ego_speed: float):
        return (self.cruise, max(0.0, ego_speed - 2.0), max(0.0, ego_speed - 5.0), 0.0)

    def _cost(self, lane, t_lane, speed, s0, t0, v0, objs, current, lanes, now) -> float:
        # Collision check along the candidate: ego moves from t0 to t_lane over ~3 s with a
        # speed ramp to `speed` at a comfortable 2 m/s^2 (braking up to 6 m/s^2).
        cost = 0.0
        s, v = s0, v0
        dt = self.dt_s
        time_gap = self.time_gap
        steps = int(self.horizon_s / dt)
        # Per-object constants of the checks below (same expressions, evaluated once).
        checks = [(os_, ov, ot, 0.5 * (owid + CAR.width_m) + 0.3, 0.5 * (olen + CAR.length_m),
                   -(olen + CAR.length_m) - 2.0)
                  for (os_, ot, ov, olen, owid) in objs]
        for k in range(1, steps + 1):
            tk = k * dt
            # The min/max below as comparisons with the builtins' results (NaN included).
            a = (speed - v) / dt
            if not a < 2.0:  # min(2.0, a)
                a = 2.0
            elif not a > -6.0:  # max(-6.0, .)
                a = -6.0
            v = v + a * dt
            if not v > 0.0:  # max(0.0, v)
                v = 0.0
            s += v * dt
            u = tk / 3.0
            if not u < 1.0:  # min(1.0, u)
                u = 1.0
            t = t0 + (t_lane - t0) * (u * u * (3 - 2 * u))
            for os_, ov, ot, lat_reach, half_len, gap_low in checks:
                if not abs(t - ot) < lat_reach:
                    continue
                gap = os_ + ov * tk - s - half_len
                # Boxes overlap along the road for -(olen + ego length) < gap < 0; keep 2 m either side.
                if gap_low < gap < 2.0:
                    return math.inf  # collision with a predicted object
                if gap >= 0.0:
                    desired = time_gap * v
                    if not desired > 5.0:  # max(5.0, desired)
                        desired = 5.0
                    if gap < desired:
                        cost += 4.0 * (desired - gap) / desired
        cost += 1.0 * abs(self.cruise - speed) / max(self.cruise, 1.0) * 10.0
        if lane != current:
            cost += 1.5 + (3.0 if now - self.last_change_s < 3.0 else 0.0)
        # Keep-right preference: right lanes have the most negative ids.
        rightmost = min(lanes) if min(lanes) < 0 else max(lanes)
        cost += 2.5 * abs(lane - rightmost)
        return cost


def _same_side(a: int, b: int) -> bool:
    return (a > 0) == (b > 0)


# ---------------------------------------------------------------- control

class Controller:
    """PID longitudinal control and path-tracking steering, at the control rate (100 Hz).

    Steering = feed-forward of the planned path's curvature (geometric angle plus the
    understeer a tyre-slip vehicle needs), previewed by `preview_s` to cover the
    actuator lag, + feedback on the lateral and course errors with gains scheduled on
    speed, so the error dynamics keep natural frequency `lateral_wn` and damping
    `lateral_zeta` at every speed. The course (direction of travel) comes from
    successive poses, so the vehicle's sideslip in a curve is not mistaken for a
    heading error. (Pure pursuit overshot lane changes at 30 m/s by ~0.8 m.)
    """

    name = "control"
    # Commands (transient), PID state (kept) and the gains (parameters in memory: a
    # changed gain stays changed for the rest of the run, like a memory upset).
    sites = ("control.steer", "control.accel", "control.integral",
             "control.kp", "control.ki", "control.kd", "control.lateral_wn", "control.understeer")
    lateral_zeta = 1.0
    preview_s = 0.2  # [s]

    def __init__(self, settings: dict, wheelbase_m: float):
        self.kp = float(settings.get("kp", 1.0))
        self.ki = float(settings.get("ki", 0.1))
        self.kd = float(settings.get("kd", 0.05))
        self.wheelbase = wheelbase_m
        self.integral = 0.0
        # Understeer gradient [rad/(m/s^2)]: steering feed-forward a tyre-slip vehicle
        # needs beyond the geometric angle in a curve.
        self.understeer = float(settings.get("understeer", 0.0028))
        self.lateral_wn = 1.0  # [rad/s] natural frequency of the lateral error dynamics
        self.prev_err = 0.0
        self.max_steer = 0.5
        self._last_xy: tuple[float, float] | None = None

    @staticmethod
    def _path(plan: Plan, s: float) -> tuple[float, float, float]:
        """Planned lateral offset t(s) [m] (smoothstep), its slope dt/ds and d2t/ds2 [1/m]."""
        length = plan.lateral_length_m
        u = min(1.0, max(0.0, (s - plan.s_start) / length))
        d = plan.t_target - plan.t_start
        if u <= 0.0 or u >= 1.0:
            return plan.t_start + d * u, 0.0, 0.0
        return (plan.t_start + d * u * u * (3 - 2 * u), d * 6.0 * u * (1.0 - u) / length,
                d * (6.0 - 12.0 * u) / (length * length))

    def _course(self, x: float, y: float, heading: float, dt: float, speed: float) -> float:
        course = heading
        if self._last_xy is not None:
            dx, dy = x - self._last_xy[0], y - self._last_xy[1]
            if dx * dx + dy * dy > (0.3 * max(speed, 1.0) * dt) ** 2 and speed > 1.0:
                course = heading + math.remainder(math.atan2(dy, dx) - heading, math.tau)
        self._last_xy = (x, y)
        return course

    def command(self, plan: Plan, ego, road, s_now: float, t_now: float, dt: float, corrupt):
        x, y, heading, speed = ego
        # The gains are read from memory every cycle and written back (persistent faults).
        self.kp = corrupt("control.kp", self.kp)
        self.ki = corrupt("control.ki", self.ki)
        self.kd = corrupt("control.kd", self.kd)
        self.lateral_wn = corrupt("control.lateral_wn", self.lateral_wn)
        self.understeer = corrupt("control.understeer", self.understeer)
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
        steer = max(-self.max_steer, min(self.max_steer, steer))
        steer = corrupt("control.steer", steer)
        # PID on speed error.
        err = plan.speed - speed
        self.integral = corrupt("control.integral", max(-5.0, min(5.0, self.integral + err * dt)))
        deriv = (err - self.prev_err) / dt
        self.prev_err = err
        accel = self.kp * err + self.ki * self.integral + self.kd * deriv
        accel = corrupt("control.accel", max(-8.0, min(3.0, accel)))
        return steer, accel
