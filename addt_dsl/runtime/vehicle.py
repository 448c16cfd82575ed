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


STATE_FIELDS = ("x", "y", "heading", "vx", "vy", "yaw_rate", "yaw_acc", "steer", "accel_cmd_actual", "accel",
                "ax_specific", "ay", "pitch", "slip_front", "slip_rear")
_STATE_DOCS = {
    "x": "[m]",
    "y": "[m]",
    "heading": "[rad]",
    "vx": "longitudinal speed in the body frame [m/s]",
    "vy": "lateral speed in the body frame [m/s]",
    "yaw_rate": "[rad/s]",
    "yaw_acc": "[rad/s^2]",
    "steer": "actual front wheel angle [rad]",
    "accel_cmd_actual": "drive/brake actuator output [m/s^2]",
    "accel": "realised longitudinal acceleration dvx/dt [m/s^2]",
    # What an accelerometer reads along the body x axis, and what shifts load between the axles.
    "ax_specific": "longitudinal specific force (tyre and drag forces / mass) [m/s^2]",
    "ay": "lateral acceleration of the cg in the body frame (dvy/dt + vx*r) [m/s^2]",
    "pitch": "road grade angle under the vehicle, nose up positive [rad]",
    "slip_front": "front axle slip angle [rad]",
    "slip_rear": "rear axle slip angle [rad]",
}


class VehicleState:
    """The dynamic state of a vehicle: its fields (`STATE_FIELDS`, SI units) are the float64
    columns of `row`, its own array or a row of a batch's block (`StateBlock`: the batch
    steps every row in one kernel call, and reads them as arrays); the attributes read and
    write that row."""

    __slots__ = ("row",)

    def __init__(self, x: float, y: float, heading: float, vx: float, vy: float = 0.0, yaw_rate: float = 0.0,
                 yaw_acc: float = 0.0, steer: float = 0.0, accel_cmd_actual: float = 0.0, accel: float = 0.0,
                 ax_specific: float = 0.0, ay: float = 0.0, pitch: float = 0.0, slip_front: float = 0.0,
                 slip_rear: float = 0.0):
        self.row = np.array([x, y, heading, vx, vy, yaw_rate, yaw_acc, steer, accel_cmd_actual, accel, ax_specific,
                             ay, pitch, slip_front, slip_rear], dtype=np.float64)

    @property
    def speed(self) -> float:
        row = self.row
        return math.hypot(row.item(VX), row.item(VY))

    def values(self) -> list[float]:
        """The fields in `STATE_FIELDS` order."""
        return self.row.tolist()

    def __eq__(self, other) -> bool:
        if other.__class__ is not self.__class__:
            return NotImplemented
        return self.row.tolist() == other.row.tolist()

    __hash__ = None  # (mutable, as the dataclass it was)

    def __repr__(self) -> str:
        return "VehicleState(" + ", ".join(f"{f}={v!r}" for f, v in zip(STATE_FIELDS, self.row.tolist())) + ")"


def _field(column: int, doc: str) -> property:
    def get(self) -> float:
        return self.row.item(column)

    def put(self, value: float) -> None:
        self.row[column] = value

    return property(get, put, doc=doc)


for _column, _name in enumerate(STATE_FIELDS):
    setattr(VehicleState, _name, _field(_column, _STATE_DOCS[_name]))
del _column, _name


PARAM_FIELDS = tuple(f.name for f in dataclasses.fields(VehicleParams))
_param_row = operator.attrgetter(*PARAM_FIELDS)


# Column of each field in a state row and a parameter row.
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


def substeps(dt: float) -> tuple[int, float]:
    """(count, length [s]) of the integration substeps of a step of `dt` [s]: at most `MAX_SUBSTEP_S` each."""
    n = max(1, math.ceil(dt / MAX_SUBSTEP_S - 1e-9))
    return n, dt / n


def step(states, params, steer_cmd, accel_cmd, dt: float, grade=0.0) -> None:
    """Advance each vehicle state in place by `dt` [s] under its steering [rad] and
    acceleration [m/s^2] commands: one state and its numbers, or sequences of them (a batch
    of runs: one compiled call over them, each run's bits the same whatever its batch).

    `grade` is the road slope dz/ds under the vehicle (uphill positive): gravity acts
    along it and the normal load shrinks by its cosine. States in a `StateBlock` step there
    without a copy (`StateBlock.step`); this copies the states' rows in and out.
    """
    if isinstance(states, VehicleState):
        states, params, steer_cmd, accel_cmd, grade = [states], [params], [steer_cmd], [accel_cmd], [grade]
    k = len(states)
    n, h = substeps(dt)
    block = np.array([v.row for v in states], dtype=np.float64).reshape(k, N_STATE)
    inputs = np.array([(i, a, b, c) for i, (a, b, c) in enumerate(zip(steer_cmd, accel_cmd, grade))],
                      dtype=np.float64).reshape(k, 4)
    _step_block(block, np.array([_param_row(q) for q in params], dtype=np.float64).reshape(k, N_PARAM),
                np.full(k, n, dtype=np.int64), np.full(k, h), inputs, np.zeros(0, dtype=np.int64),
                np.zeros(0, dtype=np.bool_))
    for v, row in zip(states, block):
        v.row[:] = row


class StateBlock:
    """The states of a batch's vehicles in one (vehicles, `STATE_FIELDS`) float64 block: each
    `VehicleState` given is made a view of its row (in the order given), so that the batch
    steps any of them in one kernel call (`step`) and reads their fields as arrays
    (`records`, `step`'s finite flags), while each state's attributes still read and write its row."""

    def __init__(self, states: list[VehicleState], dts: list[float]):
        k = len(states)
        self.states = np.array([v.row for v in states], dtype=np.float64).reshape(k, N_STATE)
        for v, row in zip(states, self.states):
            v.row = row
        self.params = np.zeros((k, N_PARAM))
        self._params_of: list = [None] * k  # the VehicleParams each params row holds
        sub = [substeps(dt) for dt in dts]  # (each row's step length is its run's, fixed)
        self.n = np.array([n for n, _ in sub], dtype=np.int64)
        self.h = np.array([h for _, h in sub], dtype=np.float64)
        self._rows: list[int] = []  # (`_index`)
        self._rows_a = np.zeros(0, dtype=np.int64)
        self._out: dict[int, np.ndarray] = {}  # `records`' output by width
        self._finite = np.zeros(k, dtype=np.bool_)  # `step`'s finite flags

    def step(self, inputs: list[tuple[int, float, float, float]], params: list[VehicleParams],
             rows: list[int]) -> list[bool]:
        """Advance states in place by their step: each of `inputs` (block row, steering [rad],
        acceleration [m/s^2], grade [-]) under its parameters (`params`), as `step` does.
        Then whether the x, y and vx of each of block rows `rows` are finite."""
        held = self._params_of
        for (i, *_), q in zip(inputs, params):
            if held[i] is not q:  # (a new VehicleParams: the road's friction changed)
                self.params[i] = _param_row(q)
                held[i] = q
        _step_block(self.states, self.params, self.n, self.h, np.array(inputs, dtype=np.float64).reshape(-1, 4),
                    self.index(rows), self._finite)
        return self._finite[:len(rows)].tolist()

    def records(self, rows: list[int], columns: np.ndarray, width: int) -> list[list[float]]:
        """A recorded row of `width` fields of each of block rows `rows`: its x, y, heading,
        speed, accel, yaw rate and steer in `columns` (in that order), 0.0 elsewhere."""
        out = self._out.get(width)
        if out is None:
            out = self._out[width] = np.zeros((len(self.states), width))
        _records(self.states, self.index(rows), columns, out)
        return out[:len(rows)].tolist()

    def index(self, rows: list[int]) -> np.ndarray:
        """`rows` as an array (the last one asked, the batch's live runs, changes seldom)."""
        if rows != self._rows:
            self._rows, self._rows_a = list(rows), np.array(rows, dtype=np.int64).reshape(-1)
        return self._rows_a


@kernel
def _records(states, rows, columns, out):
    for j in range(rows.shape[0]):
        ego_record(states[rows[j]], columns, out[j])


@kernel
def ego_record(st, columns, row):
    """Of a state `st` (a block row), its x, y, heading, speed, accel, yaw rate and steer into
    `row` at `columns` (in that order)."""
    row[columns[0]], row[columns[1]], row[columns[2]] = st[X], st[Y], st[HEADING]
    row[columns[3]] = hypot(st[VX], st[VY])
    row[columns[4]], row[columns[5]], row[columns[6]] = st[ACCEL], st[YAW_RATE], st[STEER]


@kernel
def _fmin(a, b):
    return b if math.isnan(a) or b < a else a  # numpy's fmin: a NaN loses (Python's min keeps a first NaN)


@kernel
def _fmax(a, b):
    return b if math.isnan(a) or b > a else a


@kernel
def _step_block(states, params, n, h, inputs, rows, finite):
    """Each of `inputs`' rows (block row, steering, acceleration, grade): `n[r]` substeps of
    `h[r]` [s] of state row r of `states` (`STATE_FIELDS`) under its parameters (row r of
    `params`, `PARAM_FIELDS`). Then finite[j]: whether row rows[j]'s x, y and vx are finite."""
    for j in range(inputs.shape[0]):
        r = int(inputs[j, 0])
        st, p = states[r], params[r]
        steer, accel, grade = inputs[j, 1], inputs[j, 2], inputs[j, 3]
        for _ in range(n[r]):
            _substep(st, p, steer, accel, h[r], grade)
    for j in range(rows.shape[0]):
        st = states[rows[j]]
        finite[j] = math.isfinite(st[X]) and math.isfinite(st[Y]) and math.isfinite(st[VX])


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
