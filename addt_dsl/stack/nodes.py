"""The default AD stack's nodes: perception, tracking, lattice planning, control.

Each node is a small class with a rate, a latency model and named fault sites; the
stack (`addt_dsl.stack.bev`) wires them on the bus. Values flowing through a fault
site pass through `sites(name, value)`, where the fault schedule may corrupt them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


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
        from addt_dsl.runtime.sensors import _rotation

        hits = frame.data["hit_body"]
        if len(hits) == 0:
            return []
        ids, counts = np.unique(hits, return_counts=True)
        x, y, heading, _ = ego_pose
        cos_h, sin_h = math.cos(heading), math.sin(heading)
        actual, nominal = sensor.actual, sensor.nominal
        rot_a = _rotation(actual.roll, actual.pitch, actual.yaw)
        rot_n = _rotation(nominal.roll, nominal.pitch, nominal.yaw)
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
    """Nearest-neighbour association with constant-velocity prediction between frames."""

    name = "tracker"
    sites = ("tracker.vx",)
    gate_m = 4.0
    max_age_s = 1.0

    def __init__(self, max_age_s: float = 1.0):
        self.max_age_s = max_age_s
        self.tracks: list[tuple[Obj, float]] = []  # (object, last update time)

    def update(self, objs: list[Obj], stamp_s: float, corrupt) -> None:
        predicted = [(self._predict(o, stamp_s - ts), ts) for o, ts in self.tracks]
        new_tracks = []
        used = set()
        for det in objs:
            best, best_d = None, self.gate_m
            for i, (p, ts) in enumerate(predicted):
                if i in used:
                    continue
                d = math.hypot(p.x - det.x, p.y - det.y)
                if d < best_d:
                    best, best_d = i, d
            if best is not None:
                used.add(best)
                prev, ts = self.tracks[best]
                dt = max(stamp_s - ts, 1e-3)
                # Blend measured displacement with the detector's velocity estimate.
                vx = 0.5 * det.vx + 0.5 * (det.x - prev.x) / dt
                vy = 0.5 * det.vy + 0.5 * (det.y - prev.y) / dt
                det = Obj(det.x, det.y, det.heading, corrupt("tracker.vx", vx), vy, det.length, det.width)
            new_tracks.append((det, stamp_s))
        # Keep unmatched tracks alive (coasting) so a dropped frame does not erase an object.
        for i, (p, ts) in enumerate(self.tracks):
            if i not in used and stamp_s - ts <= self.max_age_s:
                new_tracks.append((p, ts))
        self.tracks = new_tracks

    @staticmethod
    def _predict(o: Obj, dt: float) -> Obj:
        return Obj(o.x + o.vx * dt, o.y + o.vy * dt, o.heading, o.vx, o.vy, o.length, o.width)

    def objects_at(self, time_s: float) -> list[Obj]:
        return [self._predict(o, time_s - ts) for o, ts in self.tracks if time_s - ts <= self.max_age_s]


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
        steps = int(self.horizon_s / self.dt_s)
        for k in range(1, steps + 1):
            tk = k * self.dt_s
            a = max(-6.0, min(2.0, (speed - v) / self.dt_s))
            v = max(0.0, v + a * self.dt_s)
            s += v * self.dt_s
            u = min(1.0, tk / 3.0)
            t = t0 + (t_lane - t0) * (u * u * (3 - 2 * u))
            for (os_, ot, ov, olen, owid) in objs:
                so = os_ + ov * tk
                lat_overlap = abs(t - ot) < 0.5 * (owid + 1.9) + 0.3
                if not lat_overlap:
                    continue
                gap = so - s - 0.5 * (olen + 4.6)
                # Bodies overlap along the road while -(olen + 4.6) < gap < 0 (gap is
                # front-to-rear); keep 2 m clear at either end.
                if -(olen + 4.6) - 2.0 < gap < 0.0 or (0.0 <= gap < 2.0):
                    return math.inf  # collision with a predicted object
                if gap >= 0.0:
                    desired = max(5.0, self.time_gap * v)
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
    """PID longitudinal control and pure-pursuit steering, at the control rate (100 Hz)."""

    name = "control"
    sites = ("control.steer", "control.accel", "control.integral")

    def __init__(self, settings: dict, wheelbase_m: float):
        self.kp = float(settings.get("kp", 1.0))
        self.ki = float(settings.get("ki", 0.1))
        self.kd = float(settings.get("kd", 0.05))
        self.wheelbase = wheelbase_m
        self.integral = 0.0
        # Understeer gradient [rad/(m/s^2)]: steering feed-forward a tyre-slip vehicle
        # needs beyond the geometric (pure-pursuit) angle in a curve.
        self.understeer = float(settings.get("understeer", 0.0028))
        self.prev_err = 0.0
        self.max_steer = 0.5

    def command(self, plan: Plan, ego, road, s_now: float, t_now: float, dt: float, corrupt):
        x, y, heading, speed = ego
        # Pure pursuit on the planned lateral path (smoothstep from t_start to t_target).
        lookahead = max(8.0, 0.9 * speed)
        s_la = s_now + lookahead
        u = min(1.0, max(0.0, (s_la - plan.s_start) / plan.lateral_length_m))
        t_la = plan.t_start + (plan.t_target - plan.t_start) * (u * u * (3 - 2 * u))
        tx, ty, th = road.reference_pose(s_la)
        nx, ny = -math.sin(th), math.cos(th)
        gx, gy = tx + nx * t_la, ty + ny * t_la
        dx, dy = gx - x, gy - y
        local_y = -math.sin(heading) * dx + math.cos(heading) * dy
        ld2 = dx * dx + dy * dy
        steer = math.atan2(2.0 * self.wheelbase * local_y, max(ld2, 1e-6))
        # Pure pursuit is geometric; the feed-forward removes the steady outward offset
        # that tyre slip (understeer) leaves in long curves.
        kappa = float(road.curvature(min(s_la, road.length)))
        kappa_path = kappa / max(0.2, 1.0 - kappa * t_la)
        steer += self.understeer * speed * speed * kappa_path
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
