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


def step(states, params, steer_cmd, accel_cmd, dt: float, grade=0.0) -> None:
    """Advance each vehicle state in place by `dt` [s] under its steering [rad] and
    acceleration [m/s^2] commands: one state and its numbers, or sequences of them (a batch
    of runs; one is a batch of one: the same array code steps both).

    `grade` is the road slope dz/ds under the vehicle (uphill positive): gravity acts
    along it and the normal load shrinks by its cosine.
    """
    if isinstance(states, VehicleState):
        states, params, steer_cmd, accel_cmd, grade = [states], [params], [steer_cmd], [accel_cmd], [grade]
    # Columns of the batch: state[field] and p[field] are arrays over the runs.
    cols = np.array([_state_row(v) for v in states], dtype=float).T.copy()
    state = dict(zip(STATE_FIELDS, cols))
    p = dict(zip(PARAM_FIELDS, np.array([_param_row(q) for q in params], dtype=float).T))
    steer_cmd, accel_cmd = np.asarray(steer_cmd, dtype=float), np.asarray(accel_cmd, dtype=float)
    grade = np.asarray(grade, dtype=float)
    n = max(1, math.ceil(dt / MAX_SUBSTEP_S - 1e-9))
    h = dt / n
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for _ in range(n):
            _substep(state, p, steer_cmd, accel_cmd, h, grade)
    for v, row in zip(states, cols.T.tolist()):
        v.__dict__.update(zip(STATE_FIELDS, row))


def _substep(state: dict, p: dict, steer_cmd, accel_cmd, dt: float, grade) -> None:
    """One integration step over the batch's columns (arrays over runs), in place. Both
    regimes are computed and selected per run (`np.where`); what the other regime would
    give (e.g. a division by a zero speed) is discarded."""
    # fmin / fmax: a NaN command (a bit flip) is clamped as Python's min / max clamp it.
    mn, mx, where = np.fmin, np.fmax, np.where
    # Actuators: first-order lag, then rate limits.
    steer_target = mx(-p["max_steer_rad"], mn(p["max_steer_rad"], steer_cmd))
    d_steer = (steer_target - state["steer"]) * mn(1.0, dt / p["steer_lag_s"])
    max_d = p["steer_rate_rad_s"] * dt
    state["steer"] += mx(-max_d, mn(max_d, d_steer))
    d_acc = (accel_cmd - state["accel_cmd_actual"]) * mn(1.0, dt / p["accel_lag_s"])
    max_da = p["jerk_limit"] * dt
    state["accel_cmd_actual"] += mx(-max_da, mn(max_da, d_acc))

    theta = np.arctan(grade)
    state["pitch"][:] = theta
    m = p["mass_kg"]
    mg = m * G * np.cos(theta)  # normal load
    g_along = G * np.sin(theta)  # gravity component along the slope
    lf, L = p["cg_to_front_m"], p["wheelbase_m"]
    lr = L - lf
    mu = p["mu"]
    vx, vy, r, steer = state["vx"], state["vy"], state["yaw_rate"], state["steer"]
    fx_demand = m * mn(state["accel_cmd_actual"], p["max_drive_accel"])
    drag = p["drag"] * vx * vx
    tan_steer = np.tan(steer)
    slow = vx < KINEMATIC_BELOW_MPS

    # Kinematic regime at low speed: the path follows the wheels; the friction circle
    # still bounds the longitudinal force by what the cornering leaves.
    lateral = m * vx * vx * tan_steer / L
    f_max = np.sqrt(mx(0.0, (mu * mg) ** 2 - lateral * lateral))
    fx_k = mx(-f_max, mn(f_max, fx_demand))
    ax_k = fx_k / m - drag - g_along
    ax_k = where((vx <= 0.0) & (ax_k < 0.0), 0.0, ax_k)  # brakes hold the car; no reversing
    vx_k = mx(0.0, vx + ax_k * dt)
    yaw_k = vx_k * tan_steer / L
    # The tyres cannot turn the car harder than the friction circle leaves after the
    # longitudinal force: past that they slide and the path widens.
    ay_max = np.sqrt(mx(0.0, (mu * G) ** 2 - (fx_k / m) ** 2))
    yaw_k = where(vx_k * np.abs(yaw_k) > ay_max, np.copysign(ay_max / vx_k, yaw_k), yaw_k)

    # Dynamic regime. Axle loads with longitudinal load transfer from the last step's
    # specific force (clipped so that an axle never carries less than nothing).
    transfer = mx(-mg * lf / L, mn(mg * lr / L, m * state["ax_specific"] * p["cg_height_m"] / L))
    fz_f = mg * lr / L - transfer
    fz_r = mg * lf / L + transfer
    # Braking in proportion to the axle loads, drive by the drivetrain's split.
    share_f = where(fx_demand < 0.0, fz_f / mx(fz_f + fz_r, 1e-9), p["drive_front_share"])
    fx_f, fx_r = share_f * fx_demand, (1.0 - share_f) * fx_demand
    alpha_f = steer - np.arctan2(vy + lf * r, vx)
    alpha_r = -np.arctan2(vy - lr * r, vx)
    fyf = fiala_lateral_force(p["cornering_stiffness_front"], alpha_f, mu * fz_f)
    fyr = fiala_lateral_force(p["cornering_stiffness_rear"], alpha_r, mu * fz_r)
    fyf, fx_f = _friction_circle(fyf, fx_f, mu * fz_f)
    fyr, fx_r = _friction_circle(fyr, fx_r, mu * fz_r)
    cs, sn = np.cos(steer), np.sin(steer)
    fx_body = fx_f * cs - fyf * sn + fx_r
    fy_body = fyf * cs + fx_f * sn + fyr
    ax_d = fx_body / m + vy * r - drag - g_along
    ay_d = fy_body / m
    yaw_acc_d = (lf * (fyf * cs + fx_f * sn) - lr * fyr) / p["yaw_inertia_kgm2"]

    new_vx = where(slow, vx_k, mx(0.0, vx + ax_d * dt))
    new_vy = where(slow, 0.0, vy + (ay_d - vx * r) * dt)
    new_r = where(slow, yaw_k, r + yaw_acc_d * dt)
    state["yaw_acc"][:] = where(slow, (yaw_k - r) / dt, yaw_acc_d)
    state["accel"][:] = where(slow, ax_k, ax_d)
    state["ax_specific"][:] = where(slow, ax_k + g_along, fx_body / m - drag)
    state["ay"][:] = where(slow, vx_k * yaw_k, ay_d)
    state["slip_front"][:] = where(slow, 0.0, alpha_f)
    state["slip_rear"][:] = where(slow, 0.0, alpha_r)
    state["vx"][:], state["vy"][:], state["yaw_rate"][:] = new_vx, new_vy, new_r
    state["heading"] += new_r * dt
    c, s = np.cos(state["heading"]), np.sin(state["heading"])
    horizontal = np.cos(theta)  # x, y are the horizontal projection of the motion
    state["x"] += (new_vx * c - new_vy * s) * horizontal * dt
    state["y"] += (new_vx * s + new_vy * c) * horizontal * dt


def fiala_lateral_force(stiffness, alpha, f_max):
    """Fiala brush-model lateral force [N] at slip angle `alpha` [rad], saturating at `f_max`
    (numbers or arrays over a batch).

    Linear (`stiffness * alpha`) at small slip, cubic roll-off, full sliding at
    tan(alpha) >= 3 f_max / stiffness.
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        x = np.abs(np.tan(alpha))
        cx = stiffness * x
        force = cx - cx * cx / (3.0 * f_max) + cx * cx * cx / (27.0 * f_max * f_max)
        force = np.where(x * stiffness >= 3.0 * f_max, f_max, force)
        return np.where(f_max <= 0.0, 0.0, np.copysign(force, alpha))


def _friction_circle(fy, fx, limit):
    """Scale the tyre force vectors back onto the friction circle of radius `limit` [N]."""
    mag = np.hypot(fx, fy)
    k = np.where((mag <= limit) | (mag == 0.0), 1.0, limit / mag)
    return np.where(k == 1.0, fy, fy * k), np.where(k == 1.0, fx, fx * k)
