"""Ego vehicle dynamics: a dynamic single-track model with tyre friction and actuator lag.

Not kinematic. Per axle, the lateral tyre force comes from the slip angle through a
Fiala brush model (linear at small slip, saturating smoothly at mu * Fz), and the
combined longitudinal + lateral force is held on the friction circle of radius
mu * Fz. Axle loads include longitudinal load transfer (cg height) and the road grade;
braking is distributed in proportion to the axle loads (ideal brake balance, as ABS/EBD
achieve), drive goes to the front axle by default (front-wheel drive), so a car
ploughs outward (understeers) at the limit. Steering and drive/brake actuators have a
first-order lag followed by a rate limit.

Integrated with semi-implicit Euler at the physics step (sub-stepped to at most
`MAX_SUBSTEP_S`); below `KINEMATIC_BELOW_MPS` the model blends into the kinematic one,
where slip angles are ill-defined. Units: SI throughout (m, s, rad, kg, N).
"""

from __future__ import annotations

import dataclasses
import math
import operator
from dataclasses import dataclass

import numpy as np

from addt_dsl.kernel import hypot, kernel
from addt_dsl.kernel import pow  # the C library's, as CPython's `**`
from addt_dsl.vehicles import DEFAULT_MASS_KG, DEFAULT_MU, DEFAULT_WHEELBASE_M

G = 9.81  # [m/s^2]
MAX_SUBSTEP_S = 0.01  # explicit integration of the tyre dynamics stays stable below this
KINEMATIC_BELOW_MPS = 2.0


@dataclass
class VehicleParams:
    mass_kg: float = DEFAULT_MASS_KG
    wheelbase_m: float = DEFAULT_WHEELBASE_M
    cg_to_front_m: float = 1.215  # 0.45 * wheelbase: front-heavy, like most cars
    cg_height_m: float = 0.55
    yaw_inertia_kgm2: float = 2707.0  # ~ m * lf * lr (radius of gyration sqrt(lf * lr))
    # Cornering stiffness per axle [N/rad]. The front/rear ratio sets the understeer
    # gradient K = m/L * (lr/Cf - lf/Cr) ~ 2.8e-3 rad/(m/s^2) for the defaults.
    cornering_stiffness_front: float = 80000.0
    cornering_stiffness_rear: float = 90000.0
    mu: float = DEFAULT_MU
    max_steer_rad: float = 0.55  # front wheel angle
    steer_rate_rad_s: float = 0.8  # steering actuator rate limit (at the wheel)
    steer_lag_s: float = 0.08
    accel_lag_s: float = 0.15  # drive/brake actuator time constant
    jerk_limit: float = 40.0  # drive/brake actuator rate limit [m/s^3]
    max_drive_accel: float = 4.0  # [m/s^2] powertrain limit
    drive_front_share: float = 1.0  # 1 = front-wheel drive, 0.5 = balanced AWD
    drag: float = 0.0004  # aerodynamic drag per unit mass [1/m]: a_drag = drag * v^2

    @property
    def cg_to_rear_m(self) -> float:
        return self.wheelbase_m - self.cg_to_front_m

    @property
    def understeer_gradient(self) -> float:
        """K [rad/(m/s^2)] of the linear model: steady-state steer = L/R + K * a_y."""
        lf, lr, L = self.cg_to_front_m, self.cg_to_rear_m, self.wheelbase_m
        return self.mass_kg / L * (lr / self.cornering_stiffness_front - lf / self.cornering_stiffness_rear)

    @classmethod
    def for_vehicle(cls, mass_kg: float = DEFAULT_MASS_KG, wheelbase_m: float = DEFAULT_WHEELBASE_M,
                    mu: float = DEFAULT_MU,
                    **overrides) -> VehicleParams:
        """Parameters scaled from a 1500 kg, 2.7 m reference car to another mass and wheelbase.

        Cornering stiffness scales with the static axle load (same tyre characteristic per
        unit load), yaw inertia with m * lf * lr, so the handling balance (understeer
        gradient) is kept while mass and wheelbase change the response.
        """
        ref = cls()
        lf = 0.45 * wheelbase_m
        lr = wheelbase_m - lf
        # Static axle loads of the reference car → stiffness per unit load.
        ref_fzf = ref.mass_kg * G * ref.cg_to_rear_m / ref.wheelbase_m
        ref_fzr = ref.mass_kg * G * ref.cg_to_front_m / ref.wheelbase_m
        fzf, fzr = mass_kg * G * lr / wheelbase_m, mass_kg * G * lf / wheelbase_m
        values = dict(
            mass_kg=mass_kg, wheelbase_m=wheelbase_m, cg_to_front_m=lf, mu=mu,
            yaw_inertia_kgm2=mass_kg * lf * lr,
            cornering_stiffness_front=ref.cornering_stiffness_front * fzf / ref_fzf,
            cornering_stiffness_rear=ref.cornering_stiffness_rear * fzr / ref_fzr,
        )
        values.update(overrides)
        return cls(**values)


@dataclass
class VehicleState:
    x: float
    y: float
    heading: float
    vx: float  # longitudinal speed in the body frame [m/s]
    vy: float = 0.0  # lateral speed in the body frame [m/s]
    yaw_rate: float = 0.0
    yaw_acc: float = 0.0  # [rad/s^2]
    steer: float = 0.0  # actual front wheel angle [rad]
    accel_cmd_actual: float = 0.0  # drive/brake actuator output [m/s^2]
    accel: float = 0.0  # realised longitudinal acceleration dvx/dt [m/s^2]
    # Longitudinal specific force (tyre and drag forces / mass) [m/s^2]: what an
    # accelerometer reads along the body x axis, and what shifts load between the axles.
    ax_specific: float = 0.0
    ay: float = 0.0  # lateral acceleration of the cg in the body frame (dvy/dt + vx*r) [m/s^2]
    pitch: float = 0.0  # road grade angle under the vehicle, nose up positive [rad]
    slip_front: float = 0.0  # front axle slip angle [rad]
    slip_rear: float = 0.0  # rear axle slip angle [rad]

    @property
    def speed(self) -> float:
        return math.hypot(self.vx, self.vy)


STATE_FIELDS = tuple(f.name for f in dataclasses.fields(VehicleState))
PARAM_FIELDS = tuple(f.name for f in dataclasses.fields(VehicleParams))
_state_row = operator.attrgetter(*STATE_FIELDS)
_param_row = operator.attrgetter(*PARAM_FIELDS)


# Column of each field in the rows `step` hands its kernel.
_ST = {f: i for i, f in enumerate(STATE_FIELDS)}
_PA = {f: i for i, f in enumerate(PARAM_FIELDS)}
N_STATE, N_PARAM = len(STATE_FIELDS), len(PARAM_FIELDS)
X, Y, HEADING, VX, VY, YAW_RATE, YAW_ACC, STEER, ACCEL_CMD, ACCEL, AX_SPECIFIC, AY, PITCH, SLIP_F, SLIP_R = (
    _ST[f] for f in ("x", "y", "heading", "vx", "vy", "yaw_rate", "yaw_acc", "steer", "accel_cmd_actual", "accel",
                     "ax_specific", "ay", "pitch", "slip_front", "slip_rear"))
(MASS, WHEELBASE, CG_FRONT, CG_HEIGHT, YAW_INERTIA, C_FRONT, C_REAR, MU, MAX_STEER, STEER_RATE, STEER_LAG, ACCEL_LAG,
 JERK, MAX_DRIVE, DRIVE_FRONT, DRAG) = (
    _PA[f] for f in ("mass_kg", "wheelbase_m", "cg_to_front_m", "cg_height_m", "yaw_inertia_kgm2",
                     "cornering_stiffness_front", "cornering_stiffness_rear", "mu", "max_steer_rad", "steer_rate_rad_s",
                     "steer_lag_s", "accel_lag_s", "jerk_limit", "max_drive_accel", "drive_front_share", "drag"))


def step(states, params, steer_cmd, accel_cmd, dt: float, grade=0.0) -> None:
    """Advance each vehicle state in place by `dt` [s] under its steering [rad] and
    acceleration [m/s^2] commands: one state and its numbers, or sequences of them (a batch
    of runs: one compiled call over them, each run's bits the same whatever its batch).

    `grade` is the road slope dz/ds under the vehicle (uphill positive): gravity acts
    along it and the normal load shrinks by its cosine.
    """
    n = max(1, math.ceil(dt / MAX_SUBSTEP_S - 1e-9))
    if isinstance(states, VehicleState):
        states, params, steer_cmd, accel_cmd, grade = [states], [params], [steer_cmd], [accel_cmd], [grade]
    # One array per call (each array a numba call unboxes costs ~0.3 us): per run its state,
    # its parameters, then steer, accel and grade.
    rows = np.array([_state_row(v) + _param_row(q) + (a, b, c)
                     for v, q, a, b, c in zip(states, params, steer_cmd, accel_cmd, grade)], dtype=float)
    _step_rows(rows, n, dt / n)
    for v, row in zip(states, rows[:, :N_STATE].tolist()):
        v.__dict__.update(zip(STATE_FIELDS, row))


@kernel
def _fmin(a, b):
    return b if math.isnan(a) or b < a else a  # numpy's fmin: a NaN loses (Python's min keeps a first NaN)


@kernel
def _fmax(a, b):
    return b if math.isnan(a) or b > a else a


@kernel
def _step_rows(rows, n, h):
    """`n` substeps of `h` [s] of each row's state (its first `N_STATE` columns,
    `STATE_FIELDS`) under its parameters (the next `N_PARAM`, `PARAM_FIELDS`), steering,
    acceleration and grade (the last three)."""
    for r in range(rows.shape[0]):
        row = rows[r]
        st, p = row[:N_STATE], row[N_STATE:N_STATE + N_PARAM]
        steer, accel, grade = row[N_STATE + N_PARAM], row[N_STATE + N_PARAM + 1], row[N_STATE + N_PARAM + 2]
        for _ in range(n):
            _substep(st, p, steer, accel, h, grade)


@kernel
def _substep(st, p, steer_cmd, accel_cmd, dt, grade):
    """One integration step of a state row in place: the kinematic regime below
    `KINEMATIC_BELOW_MPS`, else the dynamic one."""
    # Actuators: first-order lag, then rate limits.
    steer_target = _fmax(-p[MAX_STEER], _fmin(p[MAX_STEER], steer_cmd))
    d_steer = (steer_target - st[STEER]) * _fmin(1.0, dt / p[STEER_LAG])
    max_d = p[STEER_RATE] * dt
    st[STEER] = st[STEER] + _fmax(-max_d, _fmin(max_d, d_steer))
    d_acc = (accel_cmd - st[ACCEL_CMD]) * _fmin(1.0, dt / p[ACCEL_LAG])
    max_da = p[JERK] * dt
    st[ACCEL_CMD] = st[ACCEL_CMD] + _fmax(-max_da, _fmin(max_da, d_acc))

    theta = math.atan(grade)
    st[PITCH] = theta
    m = p[MASS]
    mg = m * G * math.cos(theta)  # normal load
    g_along = G * math.sin(theta)  # gravity component along the slope
    fx_demand = m * _fmin(st[ACCEL_CMD], p[MAX_DRIVE])
    vx = st[VX]
    drag = p[DRAG] * vx * vx
    if vx < KINEMATIC_BELOW_MPS:
        _kinematic(st, p, dt, mg, g_along, fx_demand, drag)
    else:
        _dynamic(st, p, dt, mg, g_along, fx_demand, drag)
    st[HEADING] = heading = st[HEADING] + st[YAW_RATE] * dt
    c, s = math.cos(heading), math.sin(heading)
    horizontal = math.cos(theta)  # x, y are the horizontal projection of the motion
    vx, vy = st[VX], st[VY]
    st[X] = st[X] + (vx * c - vy * s) * horizontal * dt
    st[Y] = st[Y] + (vx * s + vy * c) * horizontal * dt


@kernel
def _kinematic(st, p, dt, mg, g_along, fx_demand, drag):
    """Kinematic regime at low speed: the path follows the wheels; the friction circle
    still bounds the longitudinal force by what the cornering leaves. Writes vx, vy, yaw
    rate, yaw acceleration, accel, specific force, lateral accel and slips."""
    m, L, mu = p[MASS], p[WHEELBASE], p[MU]
    vx, r = st[VX], st[YAW_RATE]
    tan_steer = math.tan(st[STEER])
    lateral = m * vx * vx * tan_steer / L
    f_max = math.sqrt(_fmax(0.0, pow(mu * mg, 2.0) - lateral * lateral))
    fx = _fmax(-f_max, _fmin(f_max, fx_demand))
    ax = fx / m - drag - g_along
    if vx <= 0.0 and ax < 0.0:  # brakes hold the car; no reversing
        ax = 0.0
    new_vx = _fmax(0.0, vx + ax * dt)
    yaw = new_vx * tan_steer / L
    # The tyres cannot turn the car harder than the friction circle leaves after the
    # longitudinal force: past that they slide and the path widens.
    ay_max = math.sqrt(_fmax(0.0, pow(mu * G, 2.0) - pow(fx / m, 2.0)))
    if new_vx * abs(yaw) > ay_max:
        yaw = math.copysign(ay_max / new_vx, yaw)
    st[VX], st[VY], st[YAW_RATE], st[YAW_ACC] = new_vx, 0.0, yaw, (yaw - r) / dt
    st[ACCEL], st[AX_SPECIFIC], st[AY], st[SLIP_F], st[SLIP_R] = ax, ax + g_along, new_vx * yaw, 0.0, 0.0


@kernel
def _dynamic(st, p, dt, mg, g_along, fx_demand, drag):
    """Dynamic regime: axle loads with longitudinal load transfer from the last step's
    specific force (clipped so that an axle never carries less than nothing), Fiala tyres
    on the friction circle. Writes what `_kinematic` writes."""
    m, mu = p[MASS], p[MU]
    lf, L = p[CG_FRONT], p[WHEELBASE]
    lr = L - lf
    vx, vy, r, steer = st[VX], st[VY], st[YAW_RATE], st[STEER]
    transfer = _fmax(-mg * lf / L, _fmin(mg * lr / L, m * st[AX_SPECIFIC] * p[CG_HEIGHT] / L))
    fz_f = mg * lr / L - transfer
    fz_r = mg * lf / L + transfer
    # Braking in proportion to the axle loads, drive by the drivetrain's split.
    share_f = fz_f / _fmax(fz_f + fz_r, 1e-9) if fx_demand < 0.0 else p[DRIVE_FRONT]
    fx_f, fx_r = share_f * fx_demand, (1.0 - share_f) * fx_demand
    alpha_f = steer - math.atan2(vy + lf * r, vx)
    alpha_r = -math.atan2(vy - lr * r, vx)
    fyf = fiala_lateral_force(p[C_FRONT], alpha_f, mu * fz_f)
    fyr = fiala_lateral_force(p[C_REAR], alpha_r, mu * fz_r)
    fyf, fx_f = _friction_circle(fyf, fx_f, mu * fz_f)
    fyr, fx_r = _friction_circle(fyr, fx_r, mu * fz_r)
    cs, sn = math.cos(steer), math.sin(steer)
    fx_body = fx_f * cs - fyf * sn + fx_r
    fy_body = fyf * cs + fx_f * sn + fyr
    ax = fx_body / m + vy * r - drag - g_along
    ay = fy_body / m
    yaw_acc = (lf * (fyf * cs + fx_f * sn) - lr * fyr) / p[YAW_INERTIA]
    st[VX], st[VY], st[YAW_RATE], st[YAW_ACC] = _fmax(0.0, vx + ax * dt), vy + (ay - vx * r) * dt, r + yaw_acc * dt, \
        yaw_acc
    st[ACCEL], st[AX_SPECIFIC], st[AY], st[SLIP_F], st[SLIP_R] = ax, fx_body / m - drag, ay, alpha_f, alpha_r


@kernel
def fiala_lateral_force(stiffness, alpha, f_max):
    """Fiala brush-model lateral force [N] at slip angle `alpha` [rad], saturating at `f_max`.

    Linear (`stiffness * alpha`) at small slip, cubic roll-off, full sliding at
    tan(alpha) >= 3 f_max / stiffness.
    """
    if f_max <= 0.0:
        return 0.0
    x = abs(math.tan(alpha))
    cx = stiffness * x
    if x * stiffness >= 3.0 * f_max:
        force = f_max
    else:
        force = cx - cx * cx / (3.0 * f_max) + cx * cx * cx / (27.0 * f_max * f_max)
    return math.copysign(force, alpha)


@kernel
def _friction_circle(fy, fx, limit):
    """Scale the tyre force vectors back onto the friction circle of radius `limit` [N]."""
    mag = hypot(fx, fy)
    if mag <= limit or mag == 0.0:
        return fy, fx
    k = limit / mag
    return fy * k, fx * k
