"""The stack's controller: PID speed control and path-tracking steering at the control rate.

A controller's gains, memory and the plan it follows are a row of a `ControlBlock`: one run's
controller steps through `Controller.command`, every fault site on the way; the fault-free
controllers of a batch step in one kernel call (`ControlBlock.command`) over the same
kernels (`_steer`, `_integrate`, `_accel`), so both give the same bits.
"""

from __future__ import annotations

import math

import numpy as np

from addt_dsl.kernel import Libm, kernel
from addt_dsl.runtime.fastroad import curvature_at, project_hinted, reference_pose_at
from addt_dsl.specs import stacks as S
from addt_dsl.stack.nodes import EgoBody, Plan

remainder = Libm("remainder", math.remainder, 2)  # exact: the C library's is CPython's

# A controller's row: its gains and memory (what the fault sites read and write back), the
# course's last position, the plan it follows, its limits and period.
(KP, KI, KD, WN, UNDERSTEER, INTEGRAL, PREV_ERR, HAS_LAST, LAST_X, LAST_Y,
 S_START, T_START, T_TARGET, LATERAL_M, SPEED, BRAKE,
 WHEELBASE, MAX_STEER, MAX_BRAKE, MAX_ACCEL, PERIOD) = range(21)
FIELDS = 21
PREVIEW_S = 0.2  # [s] the steering's preview of the path (covers the actuator lag)
LATERAL_ZETA = 1.0  # damping of the lateral error dynamics


@kernel
def _remainder_tau(a):
    """math.remainder(a, math.tau) [rad]: exact, so the C library's has its bits; raises
    where CPython's does (an infinite `a`)."""
    if a - a != 0.0 and a == a:
        raise ValueError("math domain error")
    return remainder(a, math.tau)


@kernel
def _smoothstep_path(s, s_start, t_start, t_target, length):
    """The planned lateral offset t(s) [m] (smoothstep from `t_start` at `s_start` to
    `t_target` over `length` [m]), its slope dt/ds and d2t/ds2 [1/m]; raises where Python's
    float division by zero does."""
    if length == 0.0:
        raise ZeroDivisionError("float division by zero")
    u = (s - s_start) / length
    u = u if u > 0.0 else 0.0  # min(1.0, max(0.0, u)) as Python's (a NaN gives 0)
    u = u if u < 1.0 else 1.0
    d = t_target - t_start
    if u <= 0.0 or u >= 1.0:
        return t_start + d * u, 0.0, 0.0
    if length * length == 0.0:
        raise ZeroDivisionError("float division by zero")
    return (t_start + d * u * u * (3 - 2 * u), d * 6.0 * u * (1.0 - u) / length,
            d * (6.0 - 12.0 * u) / (length * length))


@kernel
def _steer(tab, ds, last_i, length, s_start, t_start, t_target, lateral_m, x, y, heading, speed, has_last, last_x,
           last_y, dt, s_now, t_now, preview_s, wheelbase, understeer, wn, zeta, max_steer):
    """`Controller`'s steering [rad] (before its fault site) on the road of sample table
    `tab` (`FastRoad`), the plan's lateral path (`_smoothstep_path`), the ego at (`x`, `y`,
    `heading`, `speed`), at (`last_x`, `last_y`) a cycle ago if `has_last`."""
    # The course (direction of travel) from successive poses, where the ego moved enough.
    course = heading
    if has_last:
        dx, dy = x - last_x, y - last_y
        step = 0.3 * (1.0 if 1.0 > speed else speed) * dt
        reach = pow(step, 2.0)
        if reach - reach != 0.0 and step - step == 0.0:  # CPython's ** raises where it overflows
            raise OverflowError(34, "Numerical result out of range")
        if dx * dx + dy * dy > reach and speed > 1.0:
            course = heading + _remainder_tau(math.atan2(dy, dx) - heading)
    t_path, slope, _ = _smoothstep_path(s_now, s_start, t_start, t_target, lateral_m)
    road_heading = reference_pose_at(tab, ds, last_i, length, s_now)[2]
    e_lat = t_now - t_path
    e_course = _remainder_tau(course - road_heading - math.atan(slope))
    s_pre = s_now + speed * preview_s
    s_pre = length if length < s_pre else s_pre
    t_pre, _, bend = _smoothstep_path(s_pre, s_start, t_start, t_target, lateral_m)
    kappa_road = curvature_at(tab, ds, last_i, s_pre)
    g = 1.0 - kappa_road * t_pre
    kappa = kappa_road / (g if g > 0.2 else 0.2) + bend
    steer = wheelbase * kappa + understeer * speed * speed * kappa
    v = 5.0 if 5.0 > speed else speed  # max(speed, 5.0)
    steer -= wheelbase * (wn * wn * e_lat / (v * v) + 2.0 * zeta * wn * e_course / v)
    steer = steer if steer < max_steer else max_steer
    return steer if steer > -max_steer else -max_steer


@kernel
def _integrate(integral, err, dt):
    """The speed error's integral [m] after a period `dt` [s], held within +-5 (Python's
    max(-5.0, min(5.0, x)): a NaN gives 5)."""
    v = integral + err * dt
    v = v if v < 5.0 else 5.0
    return v if v > -5.0 else -5.0


@kernel
def _accel(err, prev_err, integral, dt, kp, ki, kd, brake, max_brake, max_accel):
    """PID on the speed error `err` [m/s] (`prev_err` a period `dt` [s] ago): the acceleration
    command [m/s^2], at most -`brake` where the plan brakes, within [-max_brake, max_accel]
    (Python's max and min: a NaN gives max_accel)."""
    deriv = (err - prev_err) / dt
    accel = kp * err + ki * integral + kd * deriv
    if brake > 0.0 and accel > -brake:  # emergency / AEB braking: at least this
        accel = -brake
    accel = accel if accel < max_accel else max_accel
    return accel if accel > -max_brake else -max_brake


@kernel
def _command_rows(tab, ds, last_i, length, rows, idx, ego, out):
    """The fault-free controllers in rows `idx` of `rows` on one road (sample table `tab`):
    for each i, the ego at ego[i] = (x, y, heading, speed, station hint [m]); out[i] = (steer
    [rad], accel [m/s^2], the new integral, the new error). The rows are not written
    (`_commit`): a row that raises leaves every row as it was."""
    for i in range(idx.shape[0]):
        r = rows[idx[i]]
        x, y, heading, speed = ego[i, 0], ego[i, 1], ego[i, 2], ego[i, 3]
        s_now, t_now = project_hinted(tab, ds, last_i, length, x, y, ego[i, 4], True)
        dt = r[PERIOD]
        steer = _steer(tab, ds, last_i, length, r[S_START], r[T_START], r[T_TARGET], r[LATERAL_M], x, y, heading,
                       speed, r[HAS_LAST] != 0.0, r[LAST_X], r[LAST_Y], dt, s_now, t_now, PREVIEW_S, r[WHEELBASE],
                       r[UNDERSTEER], r[WN], LATERAL_ZETA, r[MAX_STEER])
        err = r[SPEED] - speed
        integral = _integrate(r[INTEGRAL], err, dt)
        out[i, 0] = steer
        out[i, 1] = _accel(err, r[PREV_ERR], integral, dt, r[KP], r[KI], r[KD], r[BRAKE], r[MAX_BRAKE], r[MAX_ACCEL])
        out[i, 2] = integral
        out[i, 3] = err


@kernel
def _commit(rows, idx, ego, out):
    """Rows `idx` after `_command_rows`: the new integral and error, the course's position."""
    for i in range(idx.shape[0]):
        r = rows[idx[i]]
        r[INTEGRAL] = out[i, 2]
        r[PREV_ERR] = out[i, 3]
        r[HAS_LAST] = 1.0
        r[LAST_X] = ego[i, 0]
        r[LAST_Y] = ego[i, 1]


class ControlBlock:
    """The rows of some controllers in one (controllers, `FIELDS`) float64 array; each
    controller's `row` is a view of its own."""

    def __init__(self, controllers: list[Controller]):
        self.rows = np.array([c.row for c in controllers], dtype=float).reshape(len(controllers), FIELDS)
        for i, c in enumerate(controllers):
            c.block, c.index, c.row = self, i, self.rows[i]

    @staticmethod
    def holding(controllers: list[Controller]) -> ControlBlock:
        """The block all of `controllers` are rows of (one made for them, taking their rows, if
        they are not yet)."""
        block = controllers[0].block
        if block is None or any(c.block is not block for c in controllers):
            return ControlBlock(controllers)
        return block

    def command(self, controllers: list[Controller], egos: list[tuple], roads: list) -> list:
        """Each controller's (steer [rad], accel [m/s^2]) for its ego (x, y, heading, speed
        [m, rad, m/s], station hint [m]) on its road (a `FastRoad`), no fault sites: the
        controllers of one road in one kernel call. A controller whose cycle raises gets its
        exception in place of the pair, the others their commands."""
        n = len(controllers)
        out: list = [None] * n
        groups: dict[int, list[int]] = {}
        for i, road in enumerate(roads):
            groups.setdefault(id(road.table[0]), []).append(i)
        for members in groups.values():
            table = roads[members[0]].table
            idx = np.array([controllers[i].index for i in members], dtype=np.int64)
            ego = np.array([egos[i] for i in members], dtype=float).reshape(len(members), 5)
            res = np.empty((len(members), 4))
            try:
                _command_rows(*table, self.rows, idx, ego, res)
            except Exception:  # noqa: BLE001 - some row raised: each row alone, its own outcome
                for j, i in enumerate(members):
                    try:
                        _command_rows(*table, self.rows, idx[j:j + 1], ego[j:j + 1], res[j:j + 1])
                    except Exception as exc:  # noqa: BLE001 - the run's outcome
                        out[i] = exc
                        idx[j] = -1  # (its row is not written: the run stops)
                keep = idx >= 0
                idx, ego, res = idx[keep], ego[keep], res[keep]
                members = [i for i in members if out[i] is None]
            _commit(self.rows, idx, ego, res)
            for j, pair in enumerate(res[:, :2].tolist()):
                out[members[j]] = pair
        return out


class Controller:
    """PID longitudinal control and path-tracking steering, at the control rate (100 Hz).

    Steering = feed-forward of the planned path's curvature (geometric angle plus the
    understeer a tyre-slip vehicle needs), previewed by `preview_s` to cover the
    actuator lag, + feedback on the lateral and course errors with gains scheduled on
    speed, so the error dynamics keep natural frequency `lateral_wn` and damping
    `lateral_zeta` at every speed. The course (direction of travel) comes from
    successive poses, so the vehicle's sideslip in a curve is not mistaken for a
    heading error. (Pure pursuit overshot lane changes at 30 m/s by ~0.8 m.)

    Its state is a row of a `ControlBlock` (`row`; its own block of one until a batch's
    block takes it); the attributes read and write the row.
    """

    name = "control"
    sites = S.CONTROL_SITES
    lateral_zeta = LATERAL_ZETA
    preview_s = PREVIEW_S

    def __init__(self, settings: dict, wheelbase_m: float, body: EgoBody = EgoBody()):
        row = np.zeros(FIELDS)
        row[KP] = float(settings.get("kp", 1.0))
        row[KI] = float(settings.get("ki", 0.1))
        row[KD] = float(settings.get("kd", 0.05))
        row[WHEELBASE] = wheelbase_m
        # Understeer gradient [rad/(m/s^2)]: steering feed-forward a tyre-slip vehicle
        # needs beyond the geometric angle in a curve.
        row[UNDERSTEER] = float(settings.get("understeer", 0.0028))
        row[WN] = 1.0  # [rad/s] natural frequency of the lateral error dynamics
        row[MAX_STEER] = 0.5  # [rad]
        # Braking beyond what the tyres transmit only locks them (the twin's ideal ABS caps
        # it anyway): the command is bounded by the ego's friction.
        row[MAX_BRAKE] = body.max_brake
        row[MAX_ACCEL] = 3.0  # [m/s^2]
        row[PERIOD] = 1.0 / float(settings.get("control_rate", 100.0))  # [s]
        self.row = row
        self.block: ControlBlock | None = None
        self.index = 0

    def follow(self, plan: Plan) -> None:
        """Take `plan` as the one a block's cycle follows (`ControlBlock.command`)."""
        self.row[S_START:BRAKE + 1] = (plan.s_start, plan.t_start, plan.t_target, plan.lateral_length_m, plan.speed,
                                       plan.brake)

    def command(self, plan: Plan, ego, road, s_now: float, t_now: float, dt: float, corrupt):
        """(steer [rad], accel [m/s^2]) for `plan` with the ego at `ego` = (x, y, heading,
        speed) and (`s_now`, `t_now`) on `road`, a period `dt` [s] after the last cycle; every
        value passes its fault site (`corrupt(site, value)`). (The small kernels run as their
        Python here: the same bits, without a compiled call's overhead for one run.)"""
        r = self.row
        v = r.tolist()
        x, y, heading, speed = ego
        # The gains are read from memory every cycle and written back (persistent faults).
        kp, ki, kd = corrupt("control.kp", v[KP]), corrupt("control.ki", v[KI]), corrupt("control.kd", v[KD])
        wn, understeer = corrupt("control.lateral_wn", v[WN]), corrupt("control.understeer", v[UNDERSTEER])
        # (a site without a fault hands its value back itself: only a changed one is written)
        if not (kp is v[KP] and ki is v[KI] and kd is v[KD] and wn is v[WN] and understeer is v[UNDERSTEER]):
            r[KP:UNDERSTEER + 1] = (kp, ki, kd, wn, understeer)
        r[HAS_LAST:LAST_Y + 1] = (1.0, x, y)
        steer = _steer(*road.table, plan.s_start, plan.t_start, plan.t_target,
                       plan.lateral_length_m, x, y, heading, speed, v[HAS_LAST] != 0.0, v[LAST_X], v[LAST_Y], dt,
                       s_now, t_now, PREVIEW_S, v[WHEELBASE], understeer, wn, LATERAL_ZETA, v[MAX_STEER])
        steer = corrupt("control.steer", steer)
        err = plan.speed - speed
        integral = corrupt("control.integral", _integrate.py_func(v[INTEGRAL], err, dt))
        accel = _accel.py_func(err, v[PREV_ERR], integral, dt, kp, ki, kd, plan.brake, v[MAX_BRAKE], v[MAX_ACCEL])
        r[INTEGRAL:PREV_ERR + 1] = (integral, err)
        return steer, corrupt("control.accel", accel)

    @property
    def kp(self) -> float:
        """Proportional gain of the speed loop [1/s]."""
        return float(self.row[KP])

    @kp.setter
    def kp(self, value: float) -> None:
        self.row[KP] = value

    @property
    def ki(self) -> float:
        """Integral gain of the speed loop [1/s^2]."""
        return float(self.row[KI])

    @ki.setter
    def ki(self, value: float) -> None:
        self.row[KI] = value

    @property
    def kd(self) -> float:
        """Derivative gain of the speed loop [-]."""
        return float(self.row[KD])

    @kd.setter
    def kd(self, value: float) -> None:
        self.row[KD] = value

    @property
    def lateral_wn(self) -> float:
        """Natural frequency of the lateral error dynamics [rad/s]."""
        return float(self.row[WN])

    @lateral_wn.setter
    def lateral_wn(self, value: float) -> None:
        self.row[WN] = value

    @property
    def understeer(self) -> float:
        """Understeer gradient [rad/(m/s^2)]."""
        return float(self.row[UNDERSTEER])

    @understeer.setter
    def understeer(self, value: float) -> None:
        self.row[UNDERSTEER] = value

    @property
    def integral(self) -> float:
        """The speed error's integral [m]."""
        return float(self.row[INTEGRAL])

    @integral.setter
    def integral(self, value: float) -> None:
        self.row[INTEGRAL] = value

    @property
    def prev_err(self) -> float:
        """The speed error at the last cycle [m/s]."""
        return float(self.row[PREV_ERR])

    @prev_err.setter
    def prev_err(self, value: float) -> None:
        self.row[PREV_ERR] = value

    @property
    def wheelbase(self) -> float:
        """The ego's wheelbase [m]."""
        return float(self.row[WHEELBASE])

    @wheelbase.setter
    def wheelbase(self, value: float) -> None:
        self.row[WHEELBASE] = value

    @property
    def max_steer(self) -> float:
        """Steering limit [rad]."""
        return float(self.row[MAX_STEER])

    @max_steer.setter
    def max_steer(self, value: float) -> None:
        self.row[MAX_STEER] = value

    @property
    def max_brake(self) -> float:
        """Deceleration limit [m/s^2]: what the tyres transmit."""
        return float(self.row[MAX_BRAKE])

    @max_brake.setter
    def max_brake(self, value: float) -> None:
        self.row[MAX_BRAKE] = value

    @property
    def max_accel(self) -> float:
        """Acceleration limit [m/s^2]."""
        return float(self.row[MAX_ACCEL])

    @max_accel.setter
    def max_accel(self, value: float) -> None:
        self.row[MAX_ACCEL] = value

    @property
    def last_xy(self) -> tuple[float, float] | None:
        """The ego's position [m] at the last cycle (None before the first)."""
        r = self.row
        return (float(r[LAST_X]), float(r[LAST_Y])) if r[HAS_LAST] != 0.0 else None

    @last_xy.setter
    def last_xy(self, xy: tuple[float, float] | None) -> None:
        r = self.row
        r[HAS_LAST], r[LAST_X], r[LAST_Y] = (0.0, 0.0, 0.0) if xy is None else (1.0, *xy)
