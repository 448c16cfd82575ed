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


def _libm(fn):
    """`fn` of libm (`math`) mapped over an array: numpy's vectorised sin, tan, atan... may
    differ from libm in the last bit, and a run's bits must not depend on its batch."""
    def mapped(*arrays):
        return np.array(list(map(fn, *(a.tolist() for a in np.broadcast_arrays(*arrays)))), dtype=float)
    return mapped


def _float_fmin(a: float, b: float) -> float:
    return b if a != a or b < a else a  # numpy's fmin: a NaN loses (Python's min keeps a first NaN)


def _float_fmax(a: float, b: float) -> float:
    return b if a != a or b > a else a


def _float_div(a: float, b: float) -> float:
    """a / b; by zero as numpy gives it (inf or NaN: a value the step then discards)."""
    if b:
        return a / b
    return math.nan if a == 0.0 or a != a else math.copysign(math.inf, a) * math.copysign(1.0, b)


class Ops:
    """The operations the dynamics are written in: `ARRAYS` (numpy over the runs of a batch,
    libm's transcendental functions mapped) or `FLOATS` (one run, Python floats). Both give
    the same bits for a run: one formula (`_substep`), never a scalar twin."""

    def __init__(self, **ops):
        self.__dict__.update(ops)


ARRAYS = Ops(min=np.fmin, max=np.fmax, where=np.where, div=np.divide, sqrt=np.sqrt, abs=np.abs,
             copysign=np.copysign, hypot=_libm(math.hypot), tan=_libm(math.tan), atan=_libm(math.atan),
             atan2=_libm(math.atan2), sin=_libm(math.sin), cos=_libm(math.cos),
             all=lambda c: bool(c.all()), any=lambda c: bool(c.any()), zero=np.zeros_like)
FLOATS = Ops(min=_float_fmin, max=_float_fmax, where=lambda c, a, b: a if c else b, div=_float_div, sqrt=math.sqrt,
             abs=abs, copysign=math.copysign, hypot=math.hypot, tan=math.tan, atan=math.atan, atan2=math.atan2,
             sin=math.sin, cos=math.cos, all=bool, any=bool, zero=lambda like: 0.0)


# From how many runs `step` takes the batch as arrays: each numpy call costs ~1-2 us
# whatever its size (the step makes ~100, and maps libm's functions), the float step
# 7-11 us per run. Measured per run-step on the shared 2 cores (load 5-7, bench lines in
# docs/twin.md): floats 9.7-11.5 us; arrays 21 us at 8 runs, 16 at 16, 8.1 at 64, 5.8 at 256.
ARRAY_MIN_RUNS = 64


def step(states, params, steer_cmd, accel_cmd, dt: float, grade=0.0) -> None:
    """Advance each vehicle state in place by `dt` [s] under its steering [rad] and
    acceleration [m/s^2] commands: one state and its numbers, or sequences of them (a batch
    of runs: as arrays over the runs from `ARRAY_MIN_RUNS` runs on, else run by run in
    floats; both give the same bits).

    `grade` is the road slope dz/ds under the vehicle (uphill positive): gravity acts
    along it and the normal load shrinks by its cosine.
    """
    n = max(1, math.ceil(dt / MAX_SUBSTEP_S - 1e-9))
    h = dt / n
    if isinstance(states, VehicleState):
        states, params, steer_cmd, accel_cmd, grade = [states], [params], [steer_cmd], [accel_cmd], [grade]
    if len(states) < ARRAY_MIN_RUNS:  # run by run, in floats
        for v, q, steer, accel, g in zip(states, params, steer_cmd, accel_cmd, grade):
            for _ in range(n):  # (the dataclasses' own field dicts: read and written in place)
                _substep(v.__dict__, q.__dict__, float(steer), float(accel), h, float(g), FLOATS)
        return
    # Columns of the batch: state[field] and p[field] are arrays over the runs.
    cols = np.array([_state_row(v) for v in states], dtype=float).T
    state = dict(zip(STATE_FIELDS, cols))
    p = dict(zip(PARAM_FIELDS, np.array([_param_row(q) for q in params], dtype=float).T))
    steer_cmd, accel_cmd = np.asarray(steer_cmd, dtype=float), np.asarray(accel_cmd, dtype=float)
    grade = np.asarray(grade, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for _ in range(n):
            _substep(state, p, steer_cmd, accel_cmd, h, grade, ARRAYS)
    rows = np.array([state[f] for f in STATE_FIELDS]).T.tolist()
    for v, row in zip(states, rows):
        v.__dict__.update(zip(STATE_FIELDS, row))


def _substep(state: dict, p: dict, steer_cmd, accel_cmd, dt: float, grade, o: Ops) -> None:
    """One integration step of the state (floats, or arrays over runs), in `o`'s operations.
    Each run takes its regime's result (`o.where`); a regime no run is in is not computed,
    and what the other regime would give a run (e.g. a division by a zero speed) is discarded."""
    mn, mx = o.min, o.max
    # Actuators: first-order lag, then rate limits.
    steer_target = mx(-p["max_steer_rad"], mn(p["max_steer_rad"], steer_cmd))
    d_steer = (steer_target - state["steer"]) * mn(1.0, dt / p["steer_lag_s"])
    max_d = p["steer_rate_rad_s"] * dt
    state["steer"] = state["steer"] + mx(-max_d, mn(max_d, d_steer))
    d_acc = (accel_cmd - state["accel_cmd_actual"]) * mn(1.0, dt / p["accel_lag_s"])
    max_da = p["jerk_limit"] * dt
    state["accel_cmd_actual"] = state["accel_cmd_actual"] + mx(-max_da, mn(max_da, d_acc))

    theta = o.atan(grade)
    state["pitch"] = theta
    m = p["mass_kg"]
    mg = m * G * o.cos(theta)  # normal load
    g_along = G * o.sin(theta)  # gravity component along the slope
    fx_demand = m * mn(state["accel_cmd_actual"], p["max_drive_accel"])
    vx = state["vx"]
    drag = p["drag"] * vx * vx
    slow = vx < KINEMATIC_BELOW_MPS
    args = (state, p, dt, mg, g_along, fx_demand, drag, o)
    if o.all(slow):
        out = _kinematic(*args)
    elif not o.any(slow):
        out = _dynamic(*args)
    else:
        out = tuple(o.where(slow, k, d) for k, d in zip(_kinematic(*args), _dynamic(*args)))
    (state["vx"], state["vy"], state["yaw_rate"], state["yaw_acc"], state["accel"], state["ax_specific"],
     state["ay"], state["slip_front"], state["slip_rear"]) = out
    state["heading"] = heading = state["heading"] + state["yaw_rate"] * dt
    c, s = o.cos(heading), o.sin(heading)
    horizontal = o.cos(theta)  # x, y are the horizontal projection of the motion
    vx, vy = state["vx"], state["vy"]
    state["x"] = state["x"] + (vx * c - vy * s) * horizontal * dt
    state["y"] = state["y"] + (vx * s + vy * c) * horizontal * dt


def _kinematic(state, p, dt, mg, g_along, fx_demand, drag, o) -> tuple:
    """Kinematic regime at low speed: the path follows the wheels; the friction circle
    still bounds the longitudinal force by what the cornering leaves. (vx, vy, yaw rate,
    yaw acceleration, accel, specific force, lateral accel, slips) after the step."""
    mn, mx = o.min, o.max
    m, L, mu = p["mass_kg"], p["wheelbase_m"], p["mu"]
    vx, r = state["vx"], state["yaw_rate"]
    tan_steer = o.tan(state["steer"])
    lateral = m * vx * vx * tan_steer / L
    f_max = o.sqrt(mx(0.0, (mu * mg) ** 2 - lateral * lateral))
    fx = mx(-f_max, mn(f_max, fx_demand))
    ax = fx / m - drag - g_along
    ax = o.where((vx <= 0.0) & (ax < 0.0), 0.0, ax)  # brakes hold the car; no reversing
    new_vx = mx(0.0, vx + ax * dt)
    yaw = new_vx * tan_steer / L
    # The tyres cannot turn the car harder than the friction circle leaves after the
    # longitudinal force: past that they slide and the path widens.
    ay_max = o.sqrt(mx(0.0, (mu * G) ** 2 - (fx / m) ** 2))
    yaw = o.where(new_vx * o.abs(yaw) > ay_max, o.copysign(o.div(ay_max, new_vx), yaw), yaw)
    zero = o.zero(vx)
    return new_vx, zero, yaw, (yaw - r) / dt, ax, ax + g_along, new_vx * yaw, zero, zero


def _dynamic(state, p, dt, mg, g_along, fx_demand, drag, o) -> tuple:
    """Dynamic regime: axle loads with longitudinal load transfer from the last step's
    specific force (clipped so that an axle never carries less than nothing), Fiala tyres
    on the friction circle. The same quantities as `_kinematic`."""
    mn, mx = o.min, o.max
    m, mu = p["mass_kg"], p["mu"]
    lf, L = p["cg_to_front_m"], p["wheelbase_m"]
    lr = L - lf
    vx, vy, r, steer = state["vx"], state["vy"], state["yaw_rate"], state["steer"]
    transfer = mx(-mg * lf / L, mn(mg * lr / L, m * state["ax_specific"] * p["cg_height_m"] / L))
    fz_f = mg * lr / L - transfer
    fz_r = mg * lf / L + transfer
    # Braking in proportion to the axle loads, drive by the drivetrain's split.
    share_f = o.where(fx_demand < 0.0, fz_f / mx(fz_f + fz_r, 1e-9), p["drive_front_share"])
    fx_f, fx_r = share_f * fx_demand, (1.0 - share_f) * fx_demand
    alpha_f = steer - o.atan2(vy + lf * r, vx)
    alpha_r = -o.atan2(vy - lr * r, vx)
    fyf = fiala_lateral_force(p["cornering_stiffness_front"], alpha_f, mu * fz_f, o)
    fyr = fiala_lateral_force(p["cornering_stiffness_rear"], alpha_r, mu * fz_r, o)
    fyf, fx_f = _friction_circle(fyf, fx_f, mu * fz_f, o)
    fyr, fx_r = _friction_circle(fyr, fx_r, mu * fz_r, o)
    cs, sn = o.cos(steer), o.sin(steer)
    fx_body = fx_f * cs - fyf * sn + fx_r
    fy_body = fyf * cs + fx_f * sn + fyr
    ax = fx_body / m + vy * r - drag - g_along
    ay = fy_body / m
    yaw_acc = (lf * (fyf * cs + fx_f * sn) - lr * fyr) / p["yaw_inertia_kgm2"]
    return (mx(0.0, vx + ax * dt), vy + (ay - vx * r) * dt, r + yaw_acc * dt, yaw_acc, ax, fx_body / m - drag, ay,
            alpha_f, alpha_r)


def fiala_lateral_force(stiffness, alpha, f_max, o: Ops = FLOATS):
    """Fiala brush-model lateral force [N] at slip angle `alpha` [rad], saturating at `f_max`
    (floats, or arrays over a batch with `o` = ARRAYS).

    Linear (`stiffness * alpha`) at small slip, cubic roll-off, full sliding at
    tan(alpha) >= 3 f_max / stiffness.
    """
    x = o.abs(o.tan(alpha))
    cx = stiffness * x
    force = cx - o.div(cx * cx, 3.0 * f_max) + o.div(cx * cx * cx, 27.0 * f_max * f_max)
    force = o.where(x * stiffness >= 3.0 * f_max, f_max, force)
    return o.where(f_max <= 0.0, o.zero(f_max), o.copysign(force, alpha))


def _friction_circle(fy, fx, limit, o: Ops):
    """Scale the tyre force vectors back onto the friction circle of radius `limit` [N]."""
    mag = o.hypot(fx, fy)
    inside = (mag <= limit) | (mag == 0.0)
    k = o.div(limit, mag)
    return o.where(inside, fy, fy * k), o.where(inside, fx, fx * k)
