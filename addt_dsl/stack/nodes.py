"""The default AD stack's nodes: perception, tracking, lattice planning, control.

Each node is a small class with a rate, a latency model and named fault sites; the
stack (`addt_dsl.stack.bev`) wires them on the bus. Values flowing through a fault
site pass through `sites(name, value)`, where the fault schedule may corrupt them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from addt_dsl.kernel import hypot, kernel, matmul_into, pow  # (pow: the C library's, as CPython's `**`)
from addt_dsl.plan import LIGHT_STATES
from addt_dsl.specs import stacks as S
from addt_dsl.vehicles import CAR, DEFAULT_MASS_KG, DEFAULT_MU

G = 9.81  # [m/s^2]


@dataclass(frozen=True)
class EgoBody:
    """The ego's declared body as the stack sees it: box size [m], mass [kg] and the
    tyre-road friction coefficient its braking can count on (defaults: the catalogue's car
    on dry asphalt)."""

    length_m: float = CAR.length_m
    width_m: float = CAR.width_m
    mass_kg: float = DEFAULT_MASS_KG
    mu: float = DEFAULT_MU

    @property
    def max_brake(self) -> float:
        """Largest deceleration the tyres can give [m/s^2]: mu * g (ideal ABS)."""
        return self.mu * G


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
    # Class as perception reports it: a vehicle kind of addt_dsl.vehicles ("car",
    # "pedestrian", ...), "" where the detector gives none.
    kind: str = ""
    # False for a track seen once by a detector that measures no velocity: its velocity
    # (reported as 0) is a guess, not an estimate.
    velocity_known: bool = True
    # A detection from fewer returns than perception's `min_hits` (a small object at range:
    # one 1-degree ray on a 0.5 m walker to 29 m); a track is weak until a second sighting
    # in the next frame confirms it (2 of 2), and the stack does not plan for a weak track.
    weak: bool = False
    # [m/s^2] the tracker's acceleration estimate (0 where it has none: a detection, a track
    # whose velocity comes from positions alone)
    ax: float = 0.0
    ay: float = 0.0


def vehicle_to_world(ego_pose, px: float, py: float) -> tuple[float, float]:
    """A point of the ego's vehicle frame (`px` forward, `py` left [m]) in world coordinates
    [m], the ego at `ego_pose` (x, y, heading, ...): the one place perception maps boxes out."""
    x, y, heading = ego_pose[0], ego_pose[1], ego_pose[2]
    cos_h, sin_h = math.cos(heading), math.sin(heading)
    return x + cos_h * px - sin_h * py, y + sin_h * px + cos_h * py


# ---------------------------------------------------------------- perception

@kernel
def _sensed_positions(gxy, x, y, cos_h, sin_h, rot_a, rot_n, mount_a, mount_n, out):
    """Ground-truth perception's positions [m] in the vehicle frame: each object's centre at
    (gxy[i, 0], gxy[i, 1]), 0.8 m up, into the vehicle frame (the ego at `x`, `y`, heading
    cosine and sine), then into the *actual* sensor's frame (rotation `rot_a`, mount
    `mount_a` = x, y, z) and back through the *nominal* calibration (`rot_n`, `mount_n`):
    out[i] = (forward, left). The products are `kernel.matmul`'s (its kernel, row form)."""
    m = gxy.shape[0]
    v = np.empty((m, 3))
    for i in range(m):
        dx, dy = gxy[i, 0] - x, gxy[i, 1] - y
        v[i, 0] = cos_h * dx + sin_h * dy - mount_a[0]
        v[i, 1] = -sin_h * dx + cos_h * dy - mount_a[1]
        v[i, 2] = 0.8 - mount_a[2]
    in_sensor = np.empty((m, 3))
    matmul_into(v, rot_a, in_sensor)  # each row: rot_a.T @ v
    nominal = np.empty((m, 3))
    matmul_into(in_sensor, rot_n.T, nominal)  # each row: rot_n @ it
    for i in range(m):
        out[i, 0] = nominal[i, 0] + mount_n[0]
        out[i, 1] = nominal[i, 1] + mount_n[1]


def hit_counts(hits) -> tuple[list, list]:
    """The body ids a lidar frame's returns hit (`hit_body`), ascending, and how many returns
    hit each: `np.unique(hits, return_counts=True)` as lists, in one compiled call."""
    ids, counts = _id_counts(np.asarray(hits))
    return ids.tolist(), counts.tolist()


@kernel
def _id_counts(hits):
    """(the distinct values of `hits` ascending, how often each occurs)."""
    ordered = np.sort(hits)
    ids = np.empty(ordered.size, dtype=ordered.dtype)
    counts = np.zeros(ordered.size, dtype=np.int64)
    k = 0
    for i in range(ordered.size):
        if k == 0 or ordered[i] != ids[k - 1]:
            ids[k] = ordered[i]
            k += 1
        counts[k - 1] += 1
    return ids[:k], counts[:k]


class GroundTruthPerception:
    """Objects hit by at least `min_hits` lidar returns, positions from ground truth + noise;
    objects with fewer (at least one) are reported `weak`, for the tracker to confirm.

    Positions are computed where the *actual* (possibly shifted) sensor sees them and
    mapped back with the *nominal* extrinsics, so a misaligned mount produces the
    distance-dependent errors a real stack shows.
    """

    name = "perception"
    sites = S.GROUND_TRUTH_SITES
    # [m/s] the velocity accuracy the tracker assumes: ground truth is exact, but a real
    # detector's (a radar's range rate) is good to about 0.1 m/s.
    velocity_noise_mps = 0.1

    def __init__(self, settings: dict, rng: np.random.Generator, weak_rng: np.random.Generator | None = None):
        self.noise_m = float(settings.get("perception_noise", 0.1))
        self.position_noise_m = self.noise_m  # what the tracker's filter weighs positions by
        self.min_hits = int(settings.get("min_hits", 2))
        self.rng = rng
        # Weak detections draw their noise apart: the others' draws stay what they were.
        self.weak_rng = weak_rng if weak_rng is not None else rng

    def run(self, frame, sensor, ego_pose, corrupt) -> list[Obj]:
        from addt_dsl.runtime.sensors import rotation

        hits = frame.data["hit_body"]
        if len(hits) == 0:
            return []
        ids, counts = hit_counts(hits)
        seen = [(frame.actors.get(body), count) for body, count in zip(ids, counts)]
        seen = [(gt, count) for gt, count in seen if gt is not None]  # (as they were at the capture)
        if not seen:
            return []
        x, y, heading, _ = ego_pose
        actual, nominal = sensor.actual, sensor.nominal
        where = np.empty((len(seen), 2))
        _sensed_positions(np.array([(gt.x, gt.y) for gt, _ in seen]), x, y, math.cos(heading), math.sin(heading),
                          rotation(actual.roll, actual.pitch, actual.yaw),
                          rotation(nominal.roll, nominal.pitch, nominal.yaw),
                          np.array([actual.x, actual.y, actual.z]), np.array([nominal.x, nominal.y, nominal.z]), where)
        yaw_err = (actual.yaw - nominal.yaw)
        objs = []
        for (gt, count), (px, py) in zip(seen, where.tolist()):
            vx_w = gt.speed * math.cos(gt.heading)
            vy_w = gt.speed * math.sin(gt.heading)
            rng = self.rng if count >= self.min_hits else self.weak_rng
            px = px + rng.normal(0.0, self.noise_m)
            py = py + rng.normal(0.0, self.noise_m)
            px = corrupt("perception.x", px)
            py = corrupt("perception.y", py)
            wx, wy = vehicle_to_world(ego_pose, px, py)
            objs.append(Obj(wx, wy, gt.heading - yaw_err, vx_w, vy_w, gt.length_m, gt.width_m,
                            kind=gt.kind, weak=count < self.min_hits))
        # The detection count bounds the list the downstream nodes read: a corrupted count
        # hides objects (a NaN or infinite count raises, which the loop records as detected).
        count = int(corrupt("perception.count", float(len(objs))))
        return objs[:max(0, count)]


# ---------------------------------------------------------------- tracking

# `_track_update`'s rows: a track's x, y, vx, vy, ax, ay, stamp and covariance (`Tracker`);
# a detection's x, y, vx, vy, gate speed of its class while a track's velocity is unknown
# [m/s] and its class's process noise variance [m^2/s^4]; an outcome's x, y, vx, vy,
# covariance, ax, ay.
_TRACK_COLUMNS, _DET_COLUMNS, _OUT_COLUMNS = 10, 6, 9
_ZERO_DIVISION, _OVERFLOW = 1, 2  # `_track_update`'s errors: what Python's arithmetic raised


@kernel
def _squared(a):
    """(a ** 2 as CPython gives it, 0) or (nan, `_OVERFLOW`) where CPython's raises."""
    p = pow(a, 2.0)
    if p - p != 0.0 and a - a == 0.0:
        return math.nan, _OVERFLOW
    return p, 0


@kernel
def _track_update(tracks, dets, stamp_s, gate_m, r_p, r_v, accel_gain, out, best_of):
    """`Tracker.update`'s association and filter: per detection (in order) the nearest track
    not yet taken within the gate (`best_of`, -1: none, a new track) and the filtered state
    (`out`). (number of detections done, 0) or, where the Python raised, (the detection it
    raised at, `_ZERO_DIVISION` or `_OVERFLOW`)."""
    n_t = tracks.shape[0]
    used = np.zeros(n_t, dtype=np.bool_)
    for j in range(dets.shape[0]):
        zx, zy, zvx, zvy, v_max, q = dets[j, 0], dets[j, 1], dets[j, 2], dets[j, 3], dets[j, 4], dets[j, 5]
        best, best_d = -1, math.inf
        for i in range(n_t):
            if used[i]:
                continue
            px, py, pvx, ts = tracks[i, 0], tracks[i, 1], tracks[i, 2], tracks[i, 6]
            if not math.isnan(pvx):  # predicted to the frame's stamp at its velocity
                px, py = px + pvx * (stamp_s - ts), py + tracks[i, 3] * (stamp_s - ts)
            d = hypot(px - zx, py - zy)
            if math.isnan(pvx):
                gate = gate_m + v_max * (stamp_s - ts)
            else:
                gate = gate_m
            if d < gate and d < best_d:
                best, best_d = i, d
        best_of[j] = best
        measured_v = not math.isnan(zvx)
        if best < 0:
            out[j, 0], out[j, 1], out[j, 2], out[j, 3] = zx, zy, zvx, zvy
            out[j, 4], out[j, 5], out[j, 6] = r_p, 0.0, r_v if measured_v else math.inf
            out[j, 7], out[j, 8] = 0.0, 0.0
            continue
        used[best] = True
        prev_x, prev_y, prev_vx, prev_vy = tracks[best, 0], tracks[best, 1], tracks[best, 2], tracks[best, 3]
        ts, pp, pv, vv = tracks[best, 6], tracks[best, 7], tracks[best, 8], tracks[best, 9]
        dt = stamp_s - ts
        dt = 1e-3 if 1e-3 > dt else dt  # max(dt, 1e-3)
        if math.isnan(prev_vx) and not measured_v:
            # Second sighting without a velocity: two-point start.
            x, y = zx, zy
            vx, vy = (zx - prev_x) / dt, (zy - prev_y) / dt
            dt2, err = _squared(dt)
            if err:
                return j, err
            pp, pv, vv = r_p, r_p / dt, 2.0 * r_p / dt2
        else:
            if math.isnan(prev_vx):  # a velocity-less track meets a detector's velocity
                pred_x, pred_y, pred_vx, pred_vy = prev_x, prev_y, prev_vx, prev_vy
                pv, vv = 0.0, math.inf
            else:  # predicted: the state and P <- F P F' + Q (white acceleration of variance q)
                pred_x, pred_y = prev_x + prev_vx * (stamp_s - ts), prev_y + prev_vy * (stamp_s - ts)
                pred_vx, pred_vy = prev_vx, prev_vy
                dt4, dt3 = pow(dt, 4.0), pow(dt, 3.0)
                if (dt4 - dt4 != 0.0 or dt3 - dt3 != 0.0) and dt - dt == 0.0:
                    return j, _OVERFLOW
                pp, pv, vv = (pp + 2.0 * dt * pv + dt * dt * vv + q * dt4 / 4.0,
                              pv + dt * vv + q * dt3 / 2.0,
                              vv + q * dt * dt)
            # Kalman update of both axes' (p, v) with the position, then the velocity if
            # measured (independent measurements: one after the other is the joint update).
            x, vx = pred_x, 0.0 if math.isnan(pred_vx) else pred_vx
            y, vy = pred_y, 0.0 if math.isnan(pred_vy) else pred_vy
            if math.isinf(vv):  # no velocity known yet: the position resets p, v stays unknown
                k_p, k_v = 1.0, 0.0
                pp, pv = r_p, 0.0
            else:
                s = pp + r_p
                if s == 0.0:
                    return j, _ZERO_DIVISION
                k_p, k_v = pp / s, pv / s
                pp, pv, vv = pp - k_p * pp, pv - k_p * pv, vv - k_v * pv
            x, vx = x + k_p * (zx - x), vx + k_v * (zx - x)
            y, vy = y + k_p * (zy - y), vy + k_v * (zy - y)
            if measured_v:
                if math.isinf(vv):
                    k_p, k_v = 0.0, 1.0
                    vv = r_v
                else:
                    s = vv + r_v
                    if s == 0.0:
                        return j, _ZERO_DIVISION
                    k_p, k_v = pv / s, vv / s
                    pp, pv, vv = pp - k_p * pv, pv - k_p * vv, vv - k_v * vv
                x, vx = x + k_p * (zvx - vx), vx + k_v * (zvx - vx)
                y, vy = y + k_p * (zvy - vy), vy + k_v * (zvy - vy)
        ax = ay = 0.0
        if measured_v and not math.isnan(prev_vx):
            g = accel_gain
            ax = tracks[best, 4] + g * ((vx - prev_vx) / dt - tracks[best, 4])
            ay = tracks[best, 5] + g * ((vy - prev_vy) / dt - tracks[best, 5])
        out[j, 0], out[j, 1], out[j, 2], out[j, 3] = x, y, vx, vy
        out[j, 4], out[j, 5], out[j, 6], out[j, 7], out[j, 8] = pp, pv, vv, ax, ay
    return dets.shape[0], 0



class Tracker:
    """Nearest-neighbour association and a constant-velocity Kalman filter per track.

    Per axis (x and y apart, with the same noises: one covariance serves both) the state is
    position p [m] and velocity v [m/s]:

    - motion between frames dt apart: p += v dt, with piecewise-constant white acceleration
      of std `accel_noise` [m/s^2] (by class): Q = sa^2 [[dt^4/4, dt^3/2], [dt^3/2, dt^2]];
    - measurements: the detected position, std `position_noise_m` (the detector's: ground
      truth perception's `perception_noise`), and the detector's velocity where it gives one,
      std `velocity_noise_mps`.

    A detector that measures no velocity (learned perception: `vx = vy = nan`) leaves a track
    seen once without one (`vx` nan: a tentative track, gated by a class's maximum speed since
    its first prediction has no velocity); the second sighting starts the filter from the two
    positions (what the filter gives from an unknown velocity: v = displacement / dt, variance
    2 R / dt^2).

    Acceleration: where the detector measures velocity, the change of the filtered velocity
    between updates, smoothed with gain `accel_gain` (`Obj.ax`, `ay`; the planner predicts
    braking and setting off with it). From positions alone the filtered velocity's noise
    (0.24-0.30 m/s for a car at 10 Hz) differenced over 0.1 s would be metres per s^2: no
    estimate there (0).
    """

    name = "tracker"
    sites = S.TRACKER_SITES
    state_sites = S.TRACKER_STATE_SITES
    # A track's stored fields, in memory order (`tracker.tracks`, the bit-flip fault's site):
    # the box, its velocity, the last update's stamp and the filter's covariance per axis
    # (position variance [m^2], position-velocity covariance [m^2/s], velocity variance [m^2/s^2]).
    TRACK_FIELDS = ("x", "y", "heading", "vx", "vy", "length", "width", "stamp", "var_p", "cov_pv", "var_v")
    gate_m = 4.0
    max_age_s = 1.0
    max_speed = 45.0  # [m/s] gate for a track whose velocity is not yet known
    # ... and for a detection of these classes: a walker or a bicycle that jumped further
    # is another object (a 45 m/s gate lets a pedestrian's track grab a passing car's box).
    class_max_speed = {"pedestrian": 4.0, "cyclist": 15.0}
    # [m/s^2] process noise: the acceleration a class shows in ordinary traffic (a walker
    # starting or stopping, a cyclist, a vehicle braking firmly; an obstacle moves only when
    # moved). Larger follows manoeuvres sooner and passes more position noise into the
    # velocity (docs/stack.md, "Tracking").
    accel_noise = {"pedestrian": 1.0, "cyclist": 2.0, "obstacle": 0.5}
    default_accel_noise = 3.0
    # [m] and [m/s] measurement noises when the detector states none (the learned detector's
    # position error within 40 m is 0.29 m on average: about 0.25 m per axis).
    position_noise_m = 0.25
    velocity_noise_mps = 0.1

    # [s] a weak track seen again within this (1.5 lidar periods at 10 Hz) is confirmed
    confirm_s = 0.15
    # Smoothing gain of the acceleration estimate per update: 0.5 follows a step to 87.5 %
    # in three updates (0.3 s at 10 Hz); a standing box's 0.005 m/s velocity noise gives
    # ~0.05 m/s^2.
    accel_gain = 0.5

    def __init__(self, max_age_s: float = 1.0, position_noise_m: float | None = None,
                 velocity_noise_mps: float | None = None):
        self.max_age_s = max_age_s
        if position_noise_m is not None:
            # A floor: noise-free positions would make the filter's first covariance singular.
            self.position_noise_m = max(float(position_noise_m), 1e-3)
        if velocity_noise_mps is not None:
            self.velocity_noise_mps = max(float(velocity_noise_mps), 1e-3)
        # (object, last update time, (var_p, cov_pv, var_v)); the object holds the estimate.
        self.tracks: list[tuple[Obj, float, tuple[float, float, float]]] = []

    def update(self, objs: list[Obj], stamp_s: float, corrupt) -> None:
        """Associate the detections `objs` of the frame at `stamp_s` with the tracks and
        filter them (`_track_update`: one kernel call), the fault site `tracker.vx` on each
        updated track's velocity in detection order."""
        r_p = self.position_noise_m ** 2
        r_v = self.velocity_noise_mps ** 2
        tracks = np.array([(o.x, o.y, o.vx, o.vy, o.ax, o.ay, ts, *cov) for o, ts, cov in self.tracks],
                          dtype=np.float64).reshape(len(self.tracks), _TRACK_COLUMNS)
        dets = np.array([(d.x, d.y, d.vx, d.vy, self.class_max_speed.get(d.kind, self.max_speed),
                          self.accel_noise.get(d.kind, self.default_accel_noise) ** 2) for d in objs],
                        dtype=np.float64).reshape(len(objs), _DET_COLUMNS)
        out = np.empty((len(objs), _OUT_COLUMNS))
        best_of = np.empty(len(objs), dtype=np.int64)
        done, error = _track_update(tracks, dets, stamp_s, self.gate_m, r_p, r_v, self.accel_gain, out, best_of)
        new_tracks = []
        for det, best, (x, y, vx, vy, pp, pv, vv, ax, ay) in zip(objs[:done], best_of.tolist(), out.tolist()):
            if best < 0:
                # A new track: the detection, with its velocity if the detector gives one.
                new_tracks.append((det, stamp_s, (pp, pv, vv)))
                continue
            prev, ts, _ = self.tracks[best]
            # A second sighting in a row confirms a weak track (2 of 2).
            est = Obj(x, y, det.heading, corrupt("tracker.vx", vx), vy, det.length, det.width,
                      kind=det.kind, weak=det.weak and prev.weak and stamp_s - ts > self.confirm_s, ax=ax, ay=ay)
            new_tracks.append((est, stamp_s, (pp, pv, vv)))
        if error:  # where the filter's arithmetic raised in Python, at the same detection
            raise (ZeroDivisionError("float division by zero") if error == _ZERO_DIVISION else
                   OverflowError(34, "Numerical result out of range"))
        # Keep unmatched tracks alive (coasting) so a dropped frame does not erase an object.
        used = set(best_of.tolist())
        for i, (p, ts, cov) in enumerate(self.tracks):
            if i not in used and stamp_s - ts <= self.max_age_s:
                new_tracks.append((p, ts, cov))
        self.tracks = new_tracks

    def read_state(self, site: str) -> list[tuple[str, float | int]]:
        """`tracker.tracks`: (name, value) of every field of every live track, in memory order."""
        return [(f"{i}.{name}", v) for i, (o, ts, cov) in enumerate(self.tracks)
                for name, v in zip(self.TRACK_FIELDS, (o.x, o.y, o.heading, o.vx, o.vy, o.length, o.width, ts, *cov))]

    def write_state(self, site: str, values: list[float | int]) -> None:
        n = len(self.TRACK_FIELDS)
        self.tracks = [(Obj(*values[k:k + 7], confidence=o.confidence, s=o.s, t=o.t, kind=o.kind, weak=o.weak,
                            ax=o.ax, ay=o.ay),
                        values[k + 7], tuple(values[k + 8:k + 11]))
                       for (o, _, _), k in zip(self.tracks, range(0, len(values), n))]

    @staticmethod
    def _predict(o: Obj, dt: float) -> Obj:
        if math.isnan(o.vx):  # velocity not measured yet: stays where it was seen
            return o
        return Obj(o.x + o.vx * dt, o.y + o.vy * dt, o.heading, o.vx, o.vy, o.length, o.width, kind=o.kind,
                   weak=o.weak, ax=o.ax, ay=o.ay)

    def objects_at(self, time_s: float) -> list[Obj]:
        """Predicted tracks; one whose velocity is not known yet is reported as standing still
        (`velocity_known` False: a tentative track, which the stack does not plan for)."""
        out = []
        for o, ts, _ in self.tracks:
            if time_s - ts <= self.max_age_s:
                p = self._predict(o, time_s - ts)
                out.append(p if not math.isnan(p.vx) else
                           Obj(p.x, p.y, p.heading, 0.0, 0.0, p.length, p.width, p.confidence, kind=p.kind,
                               velocity_known=False, weak=p.weak))
        return out


# ---------------------------------------------------------------- planning

def unchanged(site: str, value: float) -> float:
    """A node's `corrupt` where no fault targets its sites: every value as it is."""
    return value


@dataclass
class Plan:
    """Planner output: a target lateral offset path on the ego road and a target speed.

    `brake` [m/s^2] is a deceleration the controller applies at least (emergency braking
    or the forward-collision check's stage); `aeb_stage` and `ttc_s` are that check's
    state (0 none, 1 warn, 2 partial, 3 full braking) and time to collision [s].
    """

    lane: int
    t_target: float
    speed: float
    s_start: float
    t_start: float
    lateral_length_m: float
    stamp_s: float
    brake: float = 0.0
    aeb_stage: int = 0
    ttc_s: float = math.inf


# `stack bev lane_policy`: `keep` prefers the lane the ego started in (it changes lanes
# only when traffic makes it, and returns there after an overtake); `keep_right` prefers
# the rightmost driving lane (moves over on an empty multi-lane road); neither holds while
# that lane has a slower vehicle to overtake (`LatticePlanner._overtaking`).
LANE_POLICIES = S.LANE_POLICIES


class LatticePlanner:
    """Lane-keep / lane-change candidates × speed profiles, costed and collision-checked.

    Candidates are evaluated against predictions of the tracked objects in road coordinates
    (along the road and across it, so a crossing pedestrian is predicted into the ego's lane)
    over a fixed horizon (`predict_travel`: constant velocity, with the tracker's acceleration
    where it brakes or sets off across the road); the cheapest collision-free
    one wins. Costs: progress (speed deficit), comfort (lane changes, braking), clearance,
    and a lane preference (`lane_policy`). When no candidate is collision-free the plan
    is an emergency stop in the current lane at the deceleration the tyre-road friction
    allows (mu * g); never the cheapest of colliding candidates. The forward-collision
    check (`ForwardCollisionCheck`) runs on every plan and may add braking on top.

    Objects are `(s, t, v_s, v_t, length_along, width_across[, a_s, a_t])` in the ego road's
    frame (accelerations [m/s^2] 0 where not given).
    """

    name = "planner"
    sites = S.PLANNER_SITES
    state_sites = S.PLANNER_STATE_SITES
    horizon_s = 5.0
    dt_s = 0.5
    comfort_brake = 6.0  # [m/s^2] the speed candidates' braking limit (less where friction is lower)
    curve_decel = 2.0  # [m/s^2] slowing down for a curve ahead
    curve_preview_max_m = 150.0

    def __init__(self, settings: dict, body: EgoBody = EgoBody()):
        self.cruise = float(settings.get("cruise_speed", 25.0))
        self.max_lateral_accel = float(settings.get("max_lateral_accel", 4.0))
        self.time_gap = float(settings.get("time_gap", 1.5))
        self.lane_policy = str(settings.get("lane_policy", "keep"))
        if self.lane_policy not in LANE_POLICIES:
            raise ValueError(f"lane_policy must be one of {', '.join(LANE_POLICIES)}")
        self.lane_change_cooldown_s = float(settings.get("lane_change_cooldown", 3.0))
        self.body = body
        self.max_brake = body.max_brake
        self.brake_limit = min(self.comfort_brake, self.max_brake)
        self.fcw = ForwardCollisionCheck(settings, body)
        self.current_lane: int | None = None
        self.home_lane: int | None = None
        self.maneuver: tuple[int, float, float, float] | None = None
        self.maneuver_target = math.nan  # the offset [m] the manoeuvre steers to (lane centre or a nudge)
        self.last_change_s = -1e9
        self.emergency = False  # the last plan was an emergency stop

    def read_state(self, site: str) -> list[tuple[str, float | int]]:
        """(name, value) of the stored state in `site`; empty before the first plan."""
        if site == "planner.state":
            if self.current_lane is None:
                return []
            return [("current_lane", self.current_lane), ("home_lane", self.home_lane),
                    ("last_change_s", self.last_change_s), ("aeb_stage", self.fcw.stage),
                    ("threat_s", self.fcw.threat_s)]
        if self.maneuver is None:
            return []
        return list(zip(("lane", "s_start", "t_start", "path_length"), self.maneuver))

    def write_state(self, site: str, values: list[float | int]) -> None:
        if site == "planner.state":
            self.current_lane, self.home_lane, self.last_change_s, self.fcw.stage, self.fcw.threat_s = values
        else:
            self.maneuver = tuple(values)

    def plan(self, ego_sc, ego_speed, objs_sc, road, road_id, stamp_s, corrupt,
             ego_v_st: tuple[float, float] | None = None, stop: tuple[float, float] | None = None,
             oncoming: tuple[float, float] | None = None) -> Plan:
        """`ego_sc` = (s, t, lane); `ego_v_st` = the ego's velocity along and across the
        road [m/s] for the forward-collision check (default: `ego_speed` along it); `stop` =
        the next traffic light's stop line on the ego's road (station [m], state code);
        `oncoming` = (sight [m], speed [m/s], end station [m]) for passing through the
        oncoming lane: how far perception is sure to see an oncoming car, how fast one it has
        not seen may come, and where the pass must be over (the next junction or stop line;
        None: the ego never uses the oncoming lane)."""
        s0, t0, lane0 = ego_sc
        if self.current_lane is None:
            self.current_lane = self.home_lane = lane0
        lanes = road.driving_lane_ids(s0)
        current = self.current_lane
        home = self._home_lane(lanes)
        candidates_lanes = [l for l in lanes if abs(l - current) <= 1 and _same_side(l, current)]
        nudges = self._nudges(current, float(road.lane_center_t(current, s0)), lanes, road, s0, objs_sc) \
            if current in lanes else []
        # (offset target [m] in the current lane, wait station [m] or None) while a pass waits
        # or may start
        peek = None
        if oncoming is not None:
            candidates_lanes, peek = self._oncoming_candidates(candidates_lanes, current, home, lanes, road, s0, t0,
                                                               ego_speed, objs_sc, oncoming, bool(nudges))
            if peek is not None and peek[1] is not None and (stop is None or peek[1] < stop[0]):
                stop = (peek[1], LIGHT_STATES["red"])  # wait where the oncoming lane can be seen
        # The preference does not hold while the preferred lane has a slower vehicle to pass
        # (keeping right, or to the start lane, is the rule except when overtaking).
        pref = None if self._overtaking(home, road, s0, ego_speed, objs_sc) else home
        cands = []  # (lane, offset target [m], speed [m/s], extra cost)
        speeds = self._speeds(ego_speed)
        for lane in candidates_lanes:
            t_lane = float(road.lane_center_t(lane, s0))
            targets = [(t_lane, 0.0)]
            if lane == current:
                if peek is not None:
                    targets = [(peek[0], 0.0)]
                targets += nudges
            cands += [(lane, t_cand, speed, extra) for t_cand, extra in targets for speed in speeds]
        costs = np.empty(len(cands))
        objs_arr = objects_array(objs_sc)
        if cands:
            candidate_costs(np.array([c[0] for c in cands], dtype=np.int64),
                            np.array([c[1] for c in cands], dtype=np.float64),
                            np.array([c[2] for c in cands], dtype=np.float64),
                            *self._cost_args(s0, t0, ego_speed, objs_arr, current, pref, stamp_s),
                            costs)
        best = None
        faulted = corrupt is not unchanged  # (no fault on the planner's sites: no call per candidate)
        for (lane, t_cand, speed, extra), cost in zip(cands, costs.tolist()):
            cost = corrupt("planner.cost", cost + extra) if faulted else cost + extra
            if best is None or cost < best[0]:
                best = (cost, lane, t_cand, speed)
        brake = 0.0
        self.emergency = best is None or not best[0] < math.inf  # NaN (a corrupted cost) too
        if self.emergency:
            # Nothing comfortable is collision-free: stop straight ahead as hard as the tyres allow.
            lane = current if current in lanes else lane0
            best = (math.inf, lane, float(road.lane_center_t(lane, s0)), 0.0)
            brake = self.max_brake
        _, lane, t_lane, speed = best
        if lane != current:
            self.last_change_s = stamp_s
            self.current_lane = lane
        if speed > 0.0:
            # The lateral manoeuvre the plan publishes (below): its own curvature adds to the road's.
            if self.maneuver is None or self.maneuver[0] != lane or abs(self.maneuver_target - t_lane) > 0.05:
                lateral = (s0, t0, t_lane, self._lateral_length(road, s0, t0, t_lane, ego_speed))
            else:
                lateral = (self.maneuver[1], self.maneuver[2], t_lane, self.maneuver[3])
            cap, curve_brake = self._curve_speed(road, s0, t0, ego_speed, max(speed, ego_speed), lateral)
            speed = min(speed, cap)
            brake = max(brake, curve_brake)
        if stop is not None:  # a stop station: hold the speed so the ego stops at the line
            stop_brake = self._stop_brake(stop, s0, ego_speed)
            if stop_brake is not None:
                speed, brake = 0.0, max(brake, stop_brake)
        v_s, v_t = ego_v_st if ego_v_st is not None else (ego_speed, 0.0)
        stage, ttc, aeb_brake = self.fcw.check(s0, t0, v_s, v_t, objs_arr, stamp_s)
        if aeb_brake > brake:
            brake = aeb_brake
        if brake > 0.0:
            speed = min(speed, ego_speed)  # the speed loop must not fight the braking
        speed = corrupt("planner.speed", speed)
        t_lane = corrupt("planner.t_target", t_lane)
        # The lateral manoeuvre keeps its start while its target lane stays the same, so
        # replanning does not restart the profile (which would flatten it every cycle).
        if self.maneuver is None or self.maneuver[0] != lane or abs(self.maneuver_target - t_lane) > 0.05:
            self.maneuver = (lane, s0, t0, self._lateral_length(road, s0, t0, t_lane, ego_speed))
            self.maneuver_target = t_lane
        _, s_start, t_start, lateral_len = self.maneuver
        # The published trajectory: lateral path from (s_start, t_start) to t_target over path_length.
        t_start = corrupt("planner.t_start", t_start)
        lateral_len = corrupt("planner.path_length", lateral_len)
        return Plan(lane, t_lane, speed, s_start, t_start, lateral_len, stamp_s, brake, stage, ttc)

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
        # The curvature of the line the ego drives: offset t0 from the sampled one, or on the manoeuvre's path.
        on_path = not (lateral is None or (s0 - lateral[0]) >= lateral[3] or lateral[2] == lateral[1])
        s_start, t_start, t_target, length = lateral if on_path else (0.0, 0.0, 0.0, 1.0)
        bends, cap, needed = _curve_envelope(dist, kappa, s0, t0, on_path, s_start, t_start, t_target, length,
                                             self.max_lateral_accel, self.curve_decel, ego_speed)
        if not bends:
            return math.inf, 0.0
        if ego_speed <= cap:
            return cap, 0.0
        return cap, min(self.max_brake, needed) if needed > 0.0 else 0.0

    LATERAL_MIN_M = 30.0  # [m] a lateral manoeuvre's shortest length ...
    LATERAL_S = 3.0  # [s] ... and its duration at speed
    LATERAL_MAX_S = 8.0  # [s] the longest it is stretched to in a bend

    def _lateral_length(self, road, s0: float, t0: float, t_target: float, speed: float) -> float:
        """Length [m] of a lateral manoeuvre from offset `t0` to `t_target` [m]: 3 s at the
        ego's speed, at least 30 m, and in a bend long enough that the smoothstep's peak
        curvature (6 |d| / L^2) on top of the road's keeps the lateral acceleration under
        `max_lateral_accel` (up to 8 s; beyond, the curve speed cap slows the ego)."""
        length = max(self.LATERAL_MIN_M, self.LATERAL_S * speed)
        d = abs(t_target - t0)
        if d < 1e-3 or speed < 1.0:
            return length
        _, kappa = road.curvature_ahead(s0, length)
        k_road = float(np.max(np.abs(kappa))) if len(kappa) else 0.0
        spare = self.max_lateral_accel / (speed * speed) - k_road  # [1/m] curvature left for the manoeuvre
        need = math.sqrt(6.0 * d / spare) if spare > 0.0 else math.inf
        return min(max(length, need), max(length, self.LATERAL_MAX_S * speed))

    # Stopping at traffic lights: the ego stops `STOP_GAP_M` before a red light's line,
    # braking when the constant deceleration that stops it there reaches `STOP_DECEL`; at
    # yellow only if that takes at most `YELLOW_DECEL` (else it goes on through).
    STOP_GAP_M = 1.0
    STOP_DECEL = 2.5
    YELLOW_DECEL = 3.0

    def _stop_brake(self, stop: tuple[float, float], s0: float, speed: float) -> float | None:
        """Deceleration [m/s^2] that stops the ego at the light's line, or None (free)."""
        line_s, state = stop
        dist = line_s - (s0 + 0.5 * self.body.length_m)
        if state == LIGHT_STATES["green"] or dist < -0.5:
            return None
        if state == LIGHT_STATES["yellow"] and speed * speed > 2.0 * self.YELLOW_DECEL * max(dist, 1e-6):
            return None
        room = dist - self.STOP_GAP_M
        if room <= 0.5:
            return min(self.max_brake, max(1.0, speed / 0.2))  # at the line: stop and hold
        needed = speed * speed / (2.0 * room)
        return min(self.max_brake, needed) if needed >= self.STOP_DECEL else None

    # Overtaking: a vehicle in the preferred lane moving along it (faster than a standing
    # one, `NUDGE_STANDING_MS`) but at least `OVERTAKE_DEFICIT_MS` under the cruise speed,
    # from the horizon's reach ahead to a time gap behind (the ego returns once that far past).
    OVERTAKE_DEFICIT_MS = 2.0

    def _overtaking(self, home: int, road, s0: float, ego_speed: float, objs) -> bool:
        """Whether the preferred lane `home` holds a slower vehicle to overtake."""
        reach = self.horizon_s * max(ego_speed, self.cruise)
        behind = self.time_gap * ego_speed
        for os_, ot, ov, *_ in objs:
            if (-behind < os_ - s0 < reach and self.NUDGE_STANDING_MS < ov < self.cruise - self.OVERTAKE_DEFICIT_MS
                    and road.lane_at(os_, ot) == home):
                return True
        return False

    def _home_lane(self, lanes: list[int]) -> int:
        """The lane the `lane_policy` prefers at this station."""
        if self.lane_policy == "keep_right":
            # Right lanes have the most negative ids.
            return min(lanes) if min(lanes) < 0 else max(lanes)
        return self.home_lane if self.home_lane in lanes else self.current_lane

    # Passing within the lane: a standing object ahead that overlaps the lane only partly (a
    # car parked half on the kerb) makes a candidate in the current lane offset away from it,
    # just enough to clear it with the collision check's margin, while the ego stays within
    # `NUDGE_LANE_MARGIN_M` of its lane's edges. The offset costs `NUDGE_COST` + 1 per metre,
    # so the lane centre wins whenever it is as good.
    NUDGE_COST = 1.0
    NUDGE_LANE_MARGIN_M = 0.3  # [m] how far the ego's side may reach past its lane's edge
    NUDGE_REACH_M = 80.0  # [m] objects further ahead do not move the ego yet
    # [m/s] along the road: what stands (set when the tracker's velocity of a standing car
    # had ±1 m/s of noise; its filter leaves 0.3 m/s from positions alone)
    NUDGE_STANDING_MS = 1.5
    NUDGE_SPARE_M = 0.3  # [m] beyond the collision check's margin: perception noise, tracking error

    def _nudges(self, lane, t_lane, lanes, road, s0, objs) -> list[tuple[float, float]]:
        """(offset target [m], extra cost) of in-lane passing candidates; none without a
        partial blocker ahead."""
        others = [abs(float(road.lane_center_t(l, s0)) - t_lane) for l in lanes if l != lane]
        width = min(others) if others else 3.5
        room = 0.5 * (width - self.body.width_m) + self.NUDGE_LANE_MARGIN_M
        if room <= 0.0:
            return []
        need = 0.0
        for os_, ot, ov, ovt, _olen, owid, *_ in objs:
            if not 0.0 < os_ - s0 < self.NUDGE_REACH_M or abs(ov) > self.NUDGE_STANDING_MS or abs(ovt) > 0.3:
                continue  # only what stands: moving traffic is followed or overtaken by lane
            off = ot - t_lane
            reach = 0.5 * (owid + self.body.width_m) + 0.3 + self.NUDGE_SPARE_M
            if abs(off) < reach and abs(off) + room >= reach and abs(off) > 0.5:
                shift = -math.copysign(reach - abs(off), off)
                if need == 0.0 or shift * need > 0.0 and abs(shift) > abs(need):
                    need = shift
                elif shift * need < 0.0:
                    return []  # blockers on both sides
        if need == 0.0:
            return []
        return [(t_lane + need, self.NUDGE_COST + abs(need))]

    # Passing through the oncoming lane. A standing or slow object ahead in the ego's lane
    # (slower than `PASS_SLOW_SHARE` of the cruise speed, within `PASS_REACH_M`) makes the
    # lane over the centre line a candidate once its rear is within `PASS_START_S` x speed +
    # `PASS_START_M` of the ego's front, and only while no oncoming vehicle could reach the
    # ego's path before it is back in its lane, `PASS_MARGIN_S` included: the manoeuvre ends
    # when its rear is `PASS_GAP_M` past the last object of the group (objects closer than the
    # ego's length + 2 gaps are passed at once) and it has made `RETURN_CLEAR_SHARE` of its
    # way back (its side is then over the line), driving at its cruise speed from its speed
    # now (accelerating at 2 m/s^2): T seconds, D metres. The rule: every object in the
    # oncoming lane stays beyond D over T + margin (one coming towards the ego at its tracked
    # speed; a standing one is beyond D now), none comes from behind faster than the ego, and
    # one the ego cannot see may be just beyond its sight coming at the road's speed limit:
    # sight - v_limit x (T + margin) >= D. The sight is the distance at which its lidar is
    # sure to return `min_hits` rays from a car head-on, shortened by what stands between the
    # ego and the oncoming lane's centre line of sight (the blocker itself). A pass that
    # waits stops `PASS_WAIT_GAP_M` short of the blocker, its side `PASS_PEEK_SPARE_M` from
    # its lane's edge towards the centre line, where it sees past it. Once over the line it
    # goes on; before, a rule that no longer holds turns it back.
    PASS_REACH_M = 80.0
    PASS_SLOW_SHARE = 0.5
    # [m/s] along the road: what stands (set when a tracked standing obstacle's velocity
    # flickered by up to ±2 m/s; the tracker's filter leaves 0.3 m/s from positions alone)
    PASS_STANDING_MS = 2.5
    PASS_START_S = 3.0  # [s]
    PASS_START_M = 25.0
    PASS_GAP_M = 5.0
    PASS_MARGIN_S = 2.0  # [s]
    # The pull-out from a stand follows the 30 m minimum lateral path (`LATERAL_MIN_M`): its
    # side clears a blocker centred in a 4 m lane (the check's 0.3 m across, 2 m along) about
    # 14 m along it. From 10 m short, once the ego rolled up to wait there (Town01 with an
    # oncoming car), it could not.
    PASS_WAIT_GAP_M = 15.0
    PASS_PEEK_SPARE_M = 0.3  # [m] the waiting ego's side keeps this from its lane's edge
    PASS_ACCEL = 2.0  # [m/s^2] the candidates' speed ramp
    # The share of the return path (a smoothstep over `Plan.lateral_length_m`) after which
    # the side of a car in a 3.5 m lane is back over the centre line (the smoothstep is at
    # 0.8 of the way at 0.71 of the length).
    RETURN_CLEAR_SHARE = 0.75

    def _oncoming_candidates(self, lanes_in, current, home, lanes, road, s0, t0, v0, objs, oncoming, nudged):
        """(candidate lanes, peek) with the oncoming lane's pass added or taken away; peek =
        (offset target [m], wait station [m]) while a standing blocker waits for a clear lane,
        (offset target, None) while the pass may start."""
        own, opp = current, _across_lane(current, lanes)
        if opp is None:
            return lanes_in, None
        in_opp = not _same_side(current, home)
        if in_opp:
            own, opp = opp, current  # passing: `own` is the lane passed, the way back
        # Once it has begun to pull out, what the blocker hides no longer turns it back: it hides
        # less as the ego moves over (a standing blocker's tracked offset flickers by ±0.2 m,
        # enough to flip the rule at a threshold every few cycles: on Town01 the ego went out
        # and back until it stood too close to the blocker to pull out); what it sees still does.
        allowed, standing, rear = self._oncoming_clear(own, opp, road, s0, t0, v0, objs, *oncoming,
                                                       occlusion=not in_opp)
        t_own, t_opp = float(road.lane_center_t(own, s0)), float(road.lane_center_t(opp, s0))
        if in_opp:
            out = [*lanes_in, own]
            if not allowed and abs(t0 - t_own) < abs(t0 - t_opp):
                out.remove(opp)  # not over the line yet and no longer clear: back
            return out, None
        room = 0.5 * (abs(t_opp - t_own) - self.body.width_m) - self.PASS_PEEK_SPARE_M
        peek_t = t_own + math.copysign(max(room, 0.0), t_opp - t_own)
        if allowed:
            # Behind a standing blocker the lane keeps the offset it sees from: back at its
            # centre the blocker hides more of the oncoming lane, the rule fails and the
            # ego waits, moves over to see, and the rule holds again (it crept up to the
            # blocker, too close to pull out, on Town01).
            return [*lanes_in, opp], ((peek_t, None) if standing and not nudged else None)
        if standing and not nudged:
            return lanes_in, (peek_t, rear - self.PASS_WAIT_GAP_M)
        return lanes_in, None

    def _oncoming_clear(self, own, opp, road, s0, t0, v0, objs, sight_m, v_limit, end_s=math.inf,
                        occlusion: bool = True):
        """(the oncoming lane may be used, the blocker stands, its rear station [m]) for
        passing the group of blockers ahead in lane `own` through lane `opp`; `occlusion`:
        the sight is shortened by what stands between the ego and that lane's centre."""
        t_own, t_opp = float(road.lane_center_t(own, s0)), float(road.lane_center_t(opp, s0))
        lane_w, side = abs(t_opp - t_own), math.copysign(1.0, t_opp - t_own)
        ego_len, ego_wid = self.body.length_m, self.body.width_m
        front = s0 + 0.5 * ego_len
        v_pass = self.cruise
        blockers, others = [], []
        for o in objs:
            os_, ot, ov, ovt, olen, owid = o[:6]
            # (not what crosses the road: a walker or a turning car is waited for, not passed)
            if abs(ot - t_own) < 0.5 * (owid + ego_wid) + 0.3 and 0.0 < os_ - s0 < self.PASS_REACH_M \
                    and abs(ovt) <= 0.3 \
                    and -self.PASS_STANDING_MS < ov < max(self.PASS_SLOW_SHARE * v_pass, self.PASS_STANDING_MS):
                blockers.append((os_ - 0.5 * olen, os_ + 0.5 * olen, ov))
            else:
                others.append(o)
        if not blockers or v_pass < 1.0:
            return False, False, None
        blockers.sort()
        rear = blockers[0][0]
        if rear - front > self.PASS_START_S * v0 + self.PASS_START_M:
            return False, False, None
        far, v_far = blockers[0][1], blockers[0][2]
        standing = abs(v_far) < self.PASS_STANDING_MS
        for b_rear, b_front, b_v in blockers[1:]:
            if b_rear - far > ego_len + 2.0 * self.PASS_GAP_M:
                break
            if b_front + b_v > far + v_far:
                far, v_far = b_front, b_v
            standing = standing and abs(b_v) < self.PASS_STANDING_MS
        back = self.RETURN_CLEAR_SHARE * self._lateral_length(road, s0, t_opp, t_own, v_pass)

        def distance(t_s: float) -> float:  # the ego's centre travels this far until the end
            return far + max(v_far, 0.0) * t_s + self.PASS_GAP_M + 0.5 * ego_len + back - s0

        t_end = 0.0
        for _ in range(10):  # converges by v_far / v_pass <= PASS_SLOW_SHARE per step
            t_end = time_to_cover(0.0, distance(t_end), v0, v_pass, self.PASS_ACCEL)
        reach = distance(t_end) + 0.5 * ego_len  # the ego's front at the end, from its centre
        if s0 + reach > end_s:
            return False, standing, rear  # it would not be back before the junction or stop line
        window = t_end + self.PASS_MARGIN_S
        sight = sight_m
        # What stands between the ego and the lane's centre line.
        for os_, ot, ov, _ovt, olen, owid, *_ in objs if occlusion else ():
            x = os_ - 0.5 * olen - front
            edge, target = side * (ot - t0) + 0.5 * owid, side * (t_opp - t0)
            if x > 0.0 and edge > 0.0:
                sight = min(sight, x * target / edge if edge < target else x)
        if sight - v_limit * window < reach:
            return False, standing, rear
        for os_, ot, ov, _ovt, olen, owid, *_ in others:
            if abs(ot - t_opp) >= 0.5 * (owid + lane_w):
                continue  # not in the oncoming lane
            near = os_ - 0.5 * olen - s0
            if os_ + 0.5 * olen < s0 - ego_len:
                if ov > v0:
                    return False, standing, rear  # coming up from behind
                continue
            if near + ov * (window if ov < 0.0 else t_end) < reach:
                return False, standing, rear
        return True, standing, rear

    # [m/s] the slowest moving candidate: below 4 m/s "ego speed - 2" becomes this crawl, so
    # an ego at rest whose cruise candidate meets a blocker within the horizon can still roll
    # up to where it waits (at rest the candidates were cruise or 0, and only the tracker's
    # velocity noise, now filtered out, ever moved it).
    CRAWL_MS = 2.0

    # Prediction (`predict_travel`): an object's acceleration estimate below this is noise
    # (a steady car's, from ground truth's velocity: ~0.05 m/s^2) and it keeps its velocity;
    # across the road it sets off or speeds up to `PREDICT_CROSS_SPEED` at most (a walker
    # runs, a rider crosses at 4-6 m/s), along it only braking counts (to a stop, no reversal).
    PREDICT_ACCEL_MIN = 0.5  # [m/s^2]
    PREDICT_CROSS_SPEED = 6.0  # [m/s]

    def _speeds(self, ego_speed: float):
        return (self.cruise, max(ego_speed - 2.0, min(self.cruise, self.CRAWL_MS)), max(0.0, ego_speed - 5.0), 0.0)

    def _cost(self, lane, t_lane, speed, s0, t0, v0, objs, current, home, now) -> float:
        """Cost of one candidate (`candidate_costs`'s for a single one)."""
        out = np.empty(1)
        candidate_costs(np.array([lane], dtype=np.int64), np.array([float(t_lane)]), np.array([float(speed)]),
                        *self._cost_args(s0, t0, v0, objects_array(objs), current, home, now), out)
        return float(out[0])

    def _cost_args(self, s0, t0, v0, objs: np.ndarray, current, home, now) -> tuple:
        """`candidate_costs`'s arguments after the candidates (typed: one compiled signature)."""
        change_cost = 1.5 + (3.0 if now - self.last_change_s < self.lane_change_cooldown_s else 0.0)
        return (float(s0), float(t0), float(v0), objs, int(current), 0 if home is None else int(home),
                home is not None, change_cost, float(self.cruise), float(max(self.cruise, 1.0)),
                float(self.time_gap), float(self.brake_limit), float(self.body.length_m), float(self.body.width_m),
                float(self.horizon_s), float(self.dt_s), float(self.PREDICT_ACCEL_MIN),
                float(self.PREDICT_CROSS_SPEED))


def objects_array(objs) -> np.ndarray:
    """The planner's objects as an (n, 8) float64 array: s, t, v_s, v_t, length along, width
    across, a_s, a_t (the accelerations 0 where a tuple has only six fields)."""
    if not objs:
        return np.empty((0, 8))  # (writable, C order: the kernels' one signature)
    return np.array([o if len(o) == 8 else (*o[:6], 0.0, 0.0) for o in objs], dtype=np.float64)


@kernel
def candidate_costs(lanes, t_lanes, speeds, s0, t0, v0, objs, current, home, has_home, change_cost,
                    cruise, cruise_div, time_gap, brake_limit, ego_len, ego_wid, horizon_s, dt,
                    accel_min, cross_speed, out):
    """Cost of each candidate c (lane `lanes[c]`, offset target `t_lanes[c]` [m], speed
    `speeds[c]` [m/s]) into `out[c]`: inf where it collides with a predicted object (`objs`,
    `objects_array`); else clearance (time gap to what is ahead in its path), progress
    (speed deficit to `cruise`), a lane change (`change_cost`) and the lane preference
    (`home`, where `has_home`: not while overtaking).

    Along a candidate the ego moves from `t0` to the target over ~3 s (smoothstep) with a
    speed ramp to its speed at a comfortable 2 m/s^2 (braking up to `brake_limit`), checked
    every `dt` [s] over `horizon_s`; objects move as `predict_travel` predicts."""
    steps = int(horizon_s / dt)
    brake = -brake_limit
    path_t = np.empty(steps)  # (time, s, t, speed) of the candidate at each check
    path_s = np.empty(steps)
    path_o = np.empty(steps)
    path_v = np.empty(steps)
    for c in range(lanes.size):
        t_lane, speed = t_lanes[c], speeds[c]
        cost = 0.0
        s, v = s0, v0
        for k in range(1, steps + 1):
            tk = k * dt
            # The min/max below as comparisons with the builtins' results (NaN included).
            a = (speed - v) / dt
            if not a < 2.0:  # min(2.0, a)
                a = 2.0
            elif not a > brake:  # max(brake, .)
                a = brake
            # Exact for the step's constant acceleration (the end speed times dt fell short
            # of a braking distance by v0 * dt / 2, 5 m from 20 m/s).
            v_next = v + a * dt
            if not v_next > 0.0:  # stops within the step (max(0.0, v) for the speed)
                if a < 0.0:
                    s += v * v / (-2.0 * a)
                v_next = 0.0
            else:
                s += 0.5 * (v + v_next) * dt
            v = v_next
            u = tk / 3.0
            if not u < 1.0:  # min(1.0, u)
                u = 1.0
            path_t[k - 1], path_s[k - 1], path_v[k - 1] = tk, s, v
            path_o[k - 1] = t0 + (t_lane - t0) * (u * u * (3 - 2 * u))
        collides = False
        for j in range(objs.shape[0]):
            os_, ot, ov, ovt, olen, owid = objs[j, 0], objs[j, 1], objs[j, 2], objs[j, 3], objs[j, 4], objs[j, 5]
            a_s, a_t = objs[j, 6], objs[j, 7]
            if not (a_s * ov < 0.0 and abs(a_s) >= accel_min):
                a_s = 0.0  # only braking: a lead that speeds up is followed as if it did not
            if not abs(a_t) >= accel_min:
                a_t = 0.0
            lat_reach = 0.5 * (owid + ego_wid) + 0.3
            half_len = 0.5 * (olen + ego_len)
            gap_low = -(olen + ego_len) - 2.0
            prev = os_ - s0 - half_len
            for k in range(steps):
                tk, s, v = path_t[k], path_s[k], path_v[k]
                gap = os_ + predict_travel(ov, a_s, tk, math.inf) - s - half_len
                if abs(path_o[k] - ot - predict_travel(ovt, a_t, tk, cross_speed)) < lat_reach:
                    # Boxes overlap along the road for -(olen + ego length) < gap < 0; keep 2 m
                    # either side. The gap may jump over that window between two checks (0.5 s
                    # at a 30 m/s closing speed is 15 m): what lies between counts too.
                    if prev < gap:
                        lo, hi = prev, gap
                    else:
                        lo, hi = gap, prev
                    if lo < 2.0 and hi > gap_low:
                        collides = True  # collision with a predicted object
                        break
                    if gap >= 0.0:
                        desired = time_gap * v
                        if not desired > 5.0:  # max(5.0, desired)
                            desired = 5.0
                        if gap < desired:
                            cost += 4.0 * (desired - gap) / desired
                prev = gap
            if collides:
                break
        if collides:
            out[c] = math.inf
            continue
        cost += 1.0 * abs(cruise - speed) / cruise_div * 10.0
        lane = lanes[c]
        if lane != current:
            cost += change_cost
        if has_home:  # (not overtaking: the lane preference holds)
            cost += 2.5 * (abs(lane - home) - (1 if (lane > 0) != (home > 0) else 0))  # _lane_steps
        out[c] = cost


@kernel
def predict_travel(v: float, a: float, tau: float, v_cap: float) -> float:
    """Displacement [m] after `tau` [s] of an object at velocity `v` [m/s] accelerating at `a`
    [m/s^2]: braking (a against v) ends at rest, never reverses; speeding up ends at speed
    `v_cap` [m/s] (a speed already above it is held)."""
    if a == 0.0:
        return v * tau
    # (the phases' distances as mean speed x time: finite for an infinite a, a corrupted track's)
    if a * v < 0.0:  # braking: stops after -v / a
        t_stop = -v / a
        if tau >= t_stop:
            return 0.5 * v * t_stop
        return v * tau + 0.5 * a * tau * tau
    if abs(v) >= v_cap:
        return v * tau
    top = math.copysign(v_cap, a)
    t_top = (top - v) / a  # [s] to reach the cap
    if tau <= t_top:
        return v * tau + 0.5 * a * tau * tau
    return 0.5 * (v + top) * t_top + top * (tau - t_top)


def time_to_cover(s_from: float, s_to: float, v0: float, v_top: float, accel: float) -> float:
    """Time [s] to drive from station `s_from` to `s_to` [m] starting at `v0` [m/s] and
    accelerating at `accel` [m/s^2] up to `v_top` (or holding `v0` if that is faster)."""
    d = s_to - s_from
    if d <= 0.0:
        return 0.0
    v_top = max(v_top, v0, 0.1)
    d_acc = (v_top * v_top - v0 * v0) / (2.0 * accel)
    if d <= d_acc:
        return (math.sqrt(v0 * v0 + 2.0 * accel * d) - v0) / accel
    return (v_top - v0) / accel + (d - d_acc) / v_top


@kernel
def _curve_envelope(dist, kappa, s0, t0, on_path, s_start, t_start, t_target, length, max_lateral_accel, curve_decel,
                    ego_speed):
    """`LatticePlanner._curve_speed`'s envelope over the samples ahead (`dist` [m] past `s0`,
    the reference line's curvature `kappa` [1/m]): (any bend, the speed cap [m/s], the
    braking that reaches every bend's speed at the bend [m/s^2]). The curvature of the line
    driven: offset `t0` from the reference, or (`on_path`) the lateral manoeuvre's smoothstep
    from (`s_start`, `t_start`) to `t_target` over `length` [m] plus its own curvature (the
    controller's `_smoothstep_path`, whose Python min and max drop a NaN). As numpy gave
    it: elementwise, a NaN passing through clips, maxima and minima."""
    two_decel = 2.0 * curve_decel
    cap2, needed, bends = math.inf, -math.inf, False
    for k in range(dist.size):
        kap = kappa[k]
        if on_path:
            u = (s0 + dist[k] - s_start) / length
            if u < 0.0:  # np.clip(u, 0, 1)
                u = 0.0
            elif u > 1.0:
                u = 1.0
            d = t_target - t_start
            t_path = t_start + d * u * u * (3.0 - 2.0 * u)
            bend = d * (6.0 - 12.0 * u) / (length * length) if (u > 0.0) & (u < 1.0) else 0.0
            g = 1.0 - kap * t_path
            lane_kappa = abs(kap / (g if (g > 0.2) | (g != g) else 0.2) + bend)
        else:
            g = 1.0 - kap * t0
            lane_kappa = abs(kap) / (g if (g > 0.1) | (g != g) else 0.1)
        if not lane_kappa > 1e-6:
            continue
        bend_v2 = max_lateral_accel / lane_kappa
        v2 = bend_v2 + two_decel * dist[k]
        reach = dist[k] if (dist[k] > 1.0) | (dist[k] != dist[k]) else 1.0
        brake = (ego_speed * ego_speed - bend_v2) / (2.0 * reach)
        if not bends:
            cap2, needed, bends = v2, brake, True
        else:  # np.min, np.max: a NaN wins
            if cap2 == cap2 and (v2 < cap2 or v2 != v2):
                cap2 = v2
            if needed == needed and (brake > needed or brake != brake):
                needed = brake
    return bends, math.sqrt(cap2), needed


def _lane_steps(a: int, b: int) -> int:
    """Lanes between `a` and `b` counted as crossed: ids skip 0 at the centre line (-1 and 1
    are neighbours), so the oncoming lane's pass is one lane over, not two."""
    return abs(a - b) - (1 if (a > 0) != (b > 0) else 0)


def _same_side(a: int, b: int) -> bool:
    return (a > 0) == (b > 0)


def _across_lane(lane: int, lanes) -> int | None:
    """The driving lane over the centre line from `lane` (its innermost neighbour of the
    other direction), or None where `lane` is not beside the centre line or there is none."""
    if abs(lane) != 1:
        return None
    other = 1 if lane < 0 else -1
    return other if other in lanes else None


@kernel
def _overlap_times(a: float, b: float, c: float) -> tuple[float, float]:
    """The times τ with |a + b τ| < c (an empty interval has start > end)."""
    if b == 0.0:
        return (-math.inf, math.inf) if abs(a) < c else (math.inf, -math.inf)
    t1, t2 = (-c - a) / b, (c - a) / b
    return (t1, t2) if t1 < t2 else (t2, t1)


@kernel
def first_collision(s0, t0, v_s, v_t, objs, half_len, half_wid, margin, horizon_s):
    """`ForwardCollisionCheck.time_to_collision` over `objects_array` rows: (the first time
    [s] within `horizon_s` an object ahead overlaps the ego's box along the road and, with
    `margin` [m] to spare, across it, the closing speed then [m/s]); (inf, 0) for none. Both
    move at constant velocity (the ego at `v_s`, `v_t` [m/s] from `s0`, `t0` [m])."""
    best, closing = math.inf, 0.0
    for j in range(objs.shape[0]):
        os_, ot, ovs, ovt, olen, owid = objs[j, 0], objs[j, 1], objs[j, 2], objs[j, 3], objs[j, 4], objs[j, 5]
        d = os_ - s0
        if not d > 0.0:
            continue
        a0, a1 = _overlap_times(d, ovs - v_s, 0.5 * olen + half_len)
        l0, l1 = _overlap_times(ot - t0, ovt - v_t, 0.5 * owid + half_wid + margin)
        start = a0  # max(a0, l0, 0.0) and min(a1, l1, horizon_s) as the builtins compare (NaN too)
        if l0 > start:
            start = l0
        if 0.0 > start:
            start = 0.0
        end = a1
        if l1 < end:
            end = l1
        if horizon_s < end:
            end = horizon_s
        if start <= end and start < best:
            best, closing = start, v_s - ovs
    return best, closing


class ForwardCollisionCheck:
    """AEB-like forward-collision check on the ego's predicted path.

    The ego and each object ahead (centre ahead of the ego's) move at constant velocity
    in the road frame, along and across the road; the time to collision (TTC) is the
    first time in the next `horizon_s` their boxes overlap along the road and, with
    `lateral_margin_m` to spare, across it. Stages by the smallest TTC:

    1. warn (TTC <= `aeb_warn_ttc`, 2.6 s): an event, no braking;
    2. partial braking (TTC <= `aeb_partial_ttc`, 1.6 s) at `partial_share` (40 %) of mu * g;
    3. full braking at mu * g (TTC <= `aeb_full_ttc`, 0.9 s, or when stopping the closing
       speed within the TTC needs more than partial braking gives: v / (2 TTC) > partial).

    A braking stage is held (it can rise, not fall) while the threat stays on the
    predicted path, and for `release_s` after no object is on a collision course within
    the horizon any more (a walker's estimated velocity flickers from frame to frame, and
    a brake that lets go for one plan loses what it gained). `aeb off` disables the
    braking stages (warnings still count).
    """

    horizon_s = 4.0
    lateral_margin_m = 0.2
    partial_share = 0.4
    release_s = 0.5

    def __init__(self, settings: dict, body: EgoBody = EgoBody()):
        self.enabled = str(settings.get("aeb", "on")) == "on"
        self.warn_ttc = float(settings.get("aeb_warn_ttc", 2.6))
        self.partial_ttc = float(settings.get("aeb_partial_ttc", 1.6))
        self.full_ttc = float(settings.get("aeb_full_ttc", 0.9))
        self.body = body
        self.full_brake = body.max_brake
        self.partial_brake = self.partial_share * body.max_brake
        self.stage = 0
        self.threat_s = -math.inf  # last time an object was on a collision course [s]

    def time_to_collision(self, s0, t0, v_s, v_t, objs) -> tuple[float, float]:
        """(TTC [s], closing speed along the road [m/s]) of the first predicted collision
        with an object ahead within the horizon; (inf, 0) when there is none. `objs`: the
        planner's object tuples or their `objects_array`."""
        if not isinstance(objs, np.ndarray):
            objs = objects_array(objs)
        return first_collision(float(s0), float(t0), float(v_s), float(v_t), objs, 0.5 * self.body.length_m,
                               0.5 * self.body.width_m, float(self.lateral_margin_m), float(self.horizon_s))

    def check(self, s0, t0, v_s, v_t, objs, now: float = 0.0) -> tuple[int, float, float]:
        """(stage, TTC [s], deceleration to apply [m/s^2]) at time `now` [s]."""
        ttc, closing = self.time_to_collision(s0, t0, v_s, v_t, objs)
        if ttc == math.inf:
            if self.stage < 2 or not now - self.threat_s < self.release_s:
                self.stage = 0
                return 0, ttc, 0.0
            stage = self.stage  # still braking: the threat left the path only just now
            return stage, ttc, (self.full_brake if stage == 3 else self.partial_brake) if self.enabled else 0.0
        self.threat_s = now
        needed = closing / (2.0 * ttc) if ttc > 0.0 else math.inf
        if ttc <= self.full_ttc or (ttc <= self.partial_ttc and needed > self.partial_brake):
            stage = 3
        elif ttc <= self.partial_ttc:
            stage = 2
        elif ttc <= self.warn_ttc:
            stage = 1
        else:
            stage = 0
        if self.stage >= 2 and stage < self.stage:
            stage = self.stage  # braking holds while the threat is on the path
        self.stage = stage
        if not self.enabled or stage < 2:
            return stage, ttc, 0.0
        return stage, ttc, self.full_brake if stage == 3 else self.partial_brake
