"""Ego vehicle dynamics: a dynamic single-track model with tyre friction and actuator lag.

Not kinematic: lateral tyre forces come from slip angles (linear up to the friction
limit, then saturated on the friction circle), longitudinal force is limited by
mu * m * g, and both actuators (steering, drive/brake) have a first-order lag and a
rate limit. Integrated with semi-implicit Euler at the physics step; below 2 m/s the
model blends into the kinematic one, where slip angles are ill-defined.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

G = 9.81  # [m/s^2]


@dataclass
class VehicleParams:
    mass_kg: float = 1500.0
    wheelbase_m: float = 2.7
    cg_to_front_m: float = 1.2
    yaw_inertia_kgm2: float = 2500.0
    cornering_stiffness_front: float = 80000.0  # [N/rad]
    cornering_stiffness_rear: float = 90000.0  # [N/rad]
    mu: float = 0.8  # tyre-road friction coefficient (dry asphalt)
    max_steer_rad: float = 0.55
    steer_rate_rad_s: float = 0.8
    steer_lag_s: float = 0.08
    accel_lag_s: float = 0.15
    jerk_limit: float = 40.0  # actuator rate limit on the acceleration command [m/s^3]
    max_drive_accel: float = 4.0  # [m/s^2] engine limit
    drag: float = 0.0004  # aerodynamic drag per mass [1/m]


@dataclass
class VehicleState:
    x: float
    y: float
    heading: float
    vx: float  # longitudinal speed in the body frame [m/s]
    vy: float = 0.0  # lateral speed in the body frame [m/s]
    yaw_rate: float = 0.0
    steer: float = 0.0  # actual front wheel angle [rad]
    accel_cmd_actual: float = 0.0  # actuator output [m/s^2]
    accel: float = 0.0  # realised longitudinal acceleration [m/s^2]

    @property
    def speed(self) -> float:
        return math.hypot(self.vx, self.vy)


def step(state: VehicleState, p: VehicleParams, steer_cmd: float, accel_cmd: float, dt: float) -> None:
    """Advance `state` in place by `dt` [s] under steering [rad] and acceleration [m/s^2] commands."""
    # Actuators: first-order lag, then rate limits.
    steer_target = max(-p.max_steer_rad, min(p.max_steer_rad, steer_cmd))
    d_steer = (steer_target - state.steer) * min(1.0, dt / p.steer_lag_s)
    max_d = p.steer_rate_rad_s * dt
    state.steer += max(-max_d, min(max_d, d_steer))
    d_acc = (accel_cmd - state.accel_cmd_actual) * min(1.0, dt / p.accel_lag_s)
    max_da = p.jerk_limit * dt
    state.accel_cmd_actual += max(-max_da, min(max_da, d_acc))

    mg = p.mass_kg * G
    f_max = p.mu * mg
    a_cmd = min(state.accel_cmd_actual, p.max_drive_accel)
    fx = p.mass_kg * a_cmd
    lf = p.cg_to_front_m
    lr = p.wheelbase_m - lf
    vx = state.vx

    if vx < 2.0:
        # Kinematic regime at low speed.
        fx = max(-f_max, min(f_max, fx))
        ax = fx / p.mass_kg - p.drag * vx * vx
        if vx <= 0.0 and ax < 0.0:
            ax = 0.0
        state.vx = max(0.0, vx + ax * dt)
        state.vy = 0.0
        state.yaw_rate = state.vx * math.tan(state.steer) / p.wheelbase_m
        state.accel = ax
    else:
        alpha_f = state.steer - math.atan2(state.vy + lf * state.yaw_rate, vx)
        alpha_r = -math.atan2(state.vy - lr * state.yaw_rate, vx)
        # Static axle loads; the friction circle limits the combined tyre force per axle.
        fz_f, fz_r = mg * lr / p.wheelbase_m, mg * lf / p.wheelbase_m
        fyf = p.cornering_stiffness_front * alpha_f
        fyr = p.cornering_stiffness_rear * alpha_r
        fx_f, fx_r = 0.5 * fx, 0.5 * fx  # braking/drive split evenly
        fyf, fx_f = _friction_circle(fyf, fx_f, p.mu * fz_f)
        fyr, fx_r = _friction_circle(fyr, fx_r, p.mu * fz_r)
        fx_total = fx_f * math.cos(state.steer) - fyf * math.sin(state.steer) + fx_r
        ax = fx_total / p.mass_kg + state.vy * state.yaw_rate - p.drag * vx * vx
        ay = (fyf * math.cos(state.steer) + fx_f * math.sin(state.steer) + fyr) / p.mass_kg \
            - vx * state.yaw_rate
        yaw_acc = (lf * (fyf * math.cos(state.steer) + fx_f * math.sin(state.steer)) - lr * fyr) \
            / p.yaw_inertia_kgm2
        state.vx = max(0.0, vx + ax * dt)
        state.vy += ay * dt
        state.yaw_rate += yaw_acc * dt
        state.accel = ax
    state.heading += state.yaw_rate * dt
    c, s = math.cos(state.heading), math.sin(state.heading)
    state.x += (state.vx * c - state.vy * s) * dt
    state.y += (state.vx * s + state.vy * c) * dt


def _friction_circle(fy: float, fx: float, limit: float) -> tuple[float, float]:
    """Scale the tyre force vector back onto the friction circle of radius `limit` [N]."""
    mag = math.hypot(fx, fy)
    if mag <= limit or mag == 0.0:
        return fy, fx
    k = limit / mag
    return fy * k, fx * k
