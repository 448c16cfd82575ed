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

import math
from dataclasses import dataclass

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


def step(state: VehicleState, p: VehicleParams, steer_cmd: float, accel_cmd: float, dt: float,
         grade: float = 0.0) -> None:
    """Advance `state` in place by `dt` [s] under steering [rad] and acceleration [m/s^2] commands.

    `grade` is the road slope dz/ds under the vehicle (uphill positive): gravity acts
    along it and the normal load shrinks by its cosine.
    """
    n = max(1, math.ceil(dt / MAX_SUBSTEP_S - 1e-9))
    h = dt / n
    for _ in range(n):
        _substep(state, p, steer_cmd, accel_cmd, h, grade)


def _substep(state: VehicleState, p: VehicleParams, steer_cmd: float, accel_cmd: float, dt: float,
             grade: float) -> None:
    # Actuators: first-order lag, then rate limits.
    steer_target = max(-p.max_steer_rad, min(p.max_steer_rad, steer_cmd))
    d_steer = (steer_target - state.steer) * min(1.0, dt / p.steer_lag_s)
    max_d = p.steer_rate_rad_s * dt
    state.steer += max(-max_d, min(max_d, d_steer))
    d_acc = (accel_cmd - state.accel_cmd_actual) * min(1.0, dt / p.accel_lag_s)
    max_da = p.jerk_limit * dt
    state.accel_cmd_actual += max(-max_da, min(max_da, d_acc))

    theta = math.atan(grade) if grade else 0.0
    state.pitch = theta
    m = p.mass_kg
    mg = m * G * math.cos(theta)  # normal load
    g_along = G * math.sin(theta)  # gravity component along the slope
    lf, lr, L = p.cg_to_front_m, p.wheelbase_m - p.cg_to_front_m, p.wheelbase_m
    vx = state.vx
    fx_demand = m * min(state.accel_cmd_actual, p.max_drive_accel)
    drag = p.drag * vx * vx

    if vx < KINEMATIC_BELOW_MPS:
        # Kinematic regime at low speed: the path follows the wheels; the friction circle
        # still bounds the longitudinal force by what the cornering leaves.
        lateral = m * vx * vx * math.tan(state.steer) / L
        f_max = math.sqrt(max(0.0, (p.mu * mg) ** 2 - lateral * lateral))
        fx = max(-f_max, min(f_max, fx_demand))
        ax = fx / m - drag - g_along
        if vx <= 0.0 and ax < 0.0:
            ax = 0.0  # brakes hold the car; no reversing
        state.vx = max(0.0, vx + ax * dt)
        state.vy = 0.0
        yaw_rate = state.vx * math.tan(state.steer) / L
        # The tyres cannot turn the car harder than the friction circle leaves after the
        # longitudinal force: past that they slide and the path widens.
        ay_max = math.sqrt(max(0.0, (p.mu * G) ** 2 - (fx / m) ** 2))
        if state.vx * abs(yaw_rate) > ay_max:
            yaw_rate = math.copysign(ay_max / state.vx, yaw_rate)
        state.yaw_acc = (yaw_rate - state.yaw_rate) / dt
        state.yaw_rate = yaw_rate
        state.accel = ax
        state.ax_specific = ax + g_along
        state.ay = state.vx * state.yaw_rate
        state.slip_front = state.slip_rear = 0.0
    else:
        # Axle loads with longitudinal load transfer from the last step's specific force
        # (clipped so that an axle never carries less than nothing).
        transfer = max(-mg * lf / L, min(mg * lr / L, m * state.ax_specific * p.cg_height_m / L))
        fz_f = mg * lr / L - transfer
        fz_r = mg * lf / L + transfer
        if fx_demand < 0.0:  # braking in proportion to the axle loads
            share_f = fz_f / max(fz_f + fz_r, 1e-9)
        else:
            share_f = p.drive_front_share
        fx_f, fx_r = share_f * fx_demand, (1.0 - share_f) * fx_demand
        alpha_f = state.steer - math.atan2(state.vy + lf * state.yaw_rate, vx)
        alpha_r = -math.atan2(state.vy - lr * state.yaw_rate, vx)
        fyf = fiala_lateral_force(p.cornering_stiffness_front, alpha_f, p.mu * fz_f)
        fyr = fiala_lateral_force(p.cornering_stiffness_rear, alpha_r, p.mu * fz_r)
        fyf, fx_f = _friction_circle(fyf, fx_f, p.mu * fz_f)
        fyr, fx_r = _friction_circle(fyr, fx_r, p.mu * fz_r)
        cs, sn = math.cos(state.steer), math.sin(state.steer)
        fx_body = fx_f * cs - fyf * sn + fx_r
        fy_body = fyf * cs + fx_f * sn + fyr
        ax = fx_body / m + state.vy * state.yaw_rate - drag - g_along
        ay = fy_body / m
        yaw_acc = (lf * (fyf * cs + fx_f * sn) - lr * fyr) / p.yaw_inertia_kgm2
        state.vx = max(0.0, vx + ax * dt)
        state.vy += (ay - vx * state.yaw_rate) * dt
        state.yaw_rate += yaw_acc * dt
        state.yaw_acc = yaw_acc
        state.accel = ax
        state.ax_specific = fx_body / m - drag
        state.ay = ay
        state.slip_front, state.slip_rear = alpha_f, alpha_r
    state.heading += state.yaw_rate * dt
    c, s = math.cos(state.heading), math.sin(state.heading)
    horizontal = math.cos(theta)  # x, y are the horizontal projection of the motion
    state.x += (state.vx * c - state.vy * s) * horizontal * dt
    state.y += (state.vx * s + state.vy * c) * horizontal * dt


def fiala_lateral_force(stiffness: float, alpha: float, f_max: float) -> float:
    """Fiala brush-model lateral force [N] at slip angle `alpha` [rad], saturating at `f_max`.

    Linear (`stiffness * alpha`) at small slip, cubic roll-off, full sliding at
    tan(alpha) >= 3 f_max / stiffness.
    """
    if f_max <= 0.0:
        return 0.0
    ta = math.tan(alpha)
    x = abs(ta)
    if x * stiffness >= 3.0 * f_max:
        return math.copysign(f_max, alpha)
    cx = stiffness * x
    force = cx - cx * cx / (3.0 * f_max) + cx * cx * cx / (27.0 * f_max * f_max)
    return math.copysign(force, alpha)


def _friction_circle(fy: float, fx: float, limit: float) -> tuple[float, float]:
    """Scale the tyre force vector back onto the friction circle of radius `limit` [N]."""
    mag = math.hypot(fx, fy)
    if mag <= limit or mag == 0.0:
        return fy, fx
    k = limit / mag
    return fy * k, fx * k
