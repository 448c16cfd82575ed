"""Signal functions usable in oracles and triggers, one registered class each.

`ego.speed` and `speed(ego)` are the same signal; its canonical name is `speed(ego)`.
Each class declares its argument kinds (actor or node) and its dimension so the compiler
can check formulas; `compute` derives the signal from a `Trace`.
"""

from __future__ import annotations

import numpy as np

from addt_dsl import units
from addt_dsl.registry import SIGNALS

TTC_CAP_S = 99.0  # a TTC above this means "not closing"; keeps robustness finite


def canonical(fn: str, args: tuple[str, ...]) -> str:
    return f"{fn}({','.join(args)})"


class SignalFn:
    keyword: str = ""
    args: tuple[str, ...] = ("actor",)  # "actor" | "node" | "step" (a named step, `lead.brake_hard`)
    dim = units.DIMENSIONLESS
    boolean = False  # a state (+1 holds, -1 not), usable as a formula on its own
    # Its value at an instant needs the samples before it: oracles only (a `when` condition
    # is checked on the current state alone, where it would read 0).
    history = False
    doc = ""

    @staticmethod
    def compute(trace, args: tuple[str, ...]) -> np.ndarray:
        raise NotImplementedError


def _field_signal(field_name: str, dim, doc: str) -> type[SignalFn]:
    class _Field(SignalFn):
        keyword = field_name

        @staticmethod
        def compute(trace, args):
            return getattr(trace.actors[args[0]], field_name)

    _Field.dim = dim
    _Field.doc = doc
    _Field.__name__ = _Field.__qualname__ = f"Signal_{field_name}"
    return SIGNALS.register(_Field)


for _name, _dim, _doc in (
    ("x", units.LENGTH, "world x position of the actor's centre [m]"),
    ("y", units.LENGTH, "world y position of the actor's centre [m]"),
    ("heading", units.ANGLE, "yaw [rad]"),
    ("speed", units.SPEED, "speed [m/s]"),
    ("accel", units.ACCELERATION, "longitudinal acceleration [m/s^2]"),
    ("yaw_rate", units.ANGULAR_RATE, "yaw rate [rad/s]"),
    ("s", units.LENGTH, "station along the actor's road [m]"),
    ("t", units.LENGTH, "lateral offset from the road reference line, left positive [m]"),
    ("lane_offset", units.LENGTH, "signed offset from the centre of the actor's current lane [m]"),
    ("steer", units.ANGLE, "front wheel angle [rad]"),
    ("clearance", units.LENGTH, "gap to the nearest other actor's box, negative when overlapping [m]"),
):
    _field_signal(_name, _dim, _doc)


@SIGNALS.register
class Jerk(SignalFn):
    keyword = "jerk"
    dim = units.JERK
    history = True
    doc = "time derivative of longitudinal acceleration [m/s^3]"

    @staticmethod
    def compute(trace, args):
        a = trace.actors[args[0]].accel
        return np.gradient(a, trace.period_s) if len(a) > 1 else np.zeros_like(a)


@SIGNALS.register
class Travelled(SignalFn):
    keyword = "travelled"
    dim = units.LENGTH
    history = True
    doc = ("distance the actor's centre has covered since the start, summed over the steps [m] "
           "(CARLA's DrivenDistanceTest)")

    @staticmethod
    def compute(trace, args):
        a = trace.actors[args[0]]
        return np.concatenate(([0.0], np.cumsum(np.hypot(np.diff(a.x), np.diff(a.y)))))


@SIGNALS.register
class Distance(SignalFn):
    keyword = "distance"
    args = ("actor", "actor")
    dim = units.LENGTH
    doc = "centre-to-centre distance between two actors [m]"

    @staticmethod
    def compute(trace, args):
        a, b = trace.actors[args[0]], trace.actors[args[1]]
        return np.hypot(a.x - b.x, a.y - b.y)


@SIGNALS.register
class Gap(SignalFn):
    keyword = "gap"
    args = ("actor", "actor")
    dim = units.LENGTH
    doc = ("bumper-to-bumper gap along the road (or the shared route) from the first actor to the "
           "second; between actors on different roads or routes, the centre distance less half "
           "of both lengths [m]")

    @staticmethod
    def compute(trace, args):
        a, b = trace.actors[args[0]], trace.actors[args[1]]
        if not same_frame(a, b):
            return np.hypot(a.x - b.x, a.y - b.y) - 0.5 * (a.length_m + b.length_m)
        return (b.s - a.s) - 0.5 * (a.length_m + b.length_m)


def same_frame(a, b) -> bool:
    """Whether two actor tracks measure `s` along the same road or route (`ActorTrack.frame`)."""
    return a.frame == b.frame


@SIGNALS.register
class RelSpeed(SignalFn):
    keyword = "rel_speed"
    args = ("actor", "actor")
    dim = units.SPEED
    doc = ("speed of the first actor minus that of the second, positive when the first is faster "
           "(OpenSCENARIO RelativeSpeedCondition) [m/s]")

    @staticmethod
    def compute(trace, args):
        return trace.actors[args[0]].speed - trace.actors[args[1]].speed


@SIGNALS.register
class LatGap(SignalFn):
    keyword = "lat_gap"
    args = ("actor", "actor")
    dim = units.LENGTH
    doc = ("side-to-side gap across the road between two actors' boxes, negative when they overlap "
           "laterally (OpenSCENARIO RelativeDistanceCondition, lateral, freespace) [m]")

    @staticmethod
    def compute(trace, args):
        a, b = trace.actors[args[0]], trace.actors[args[1]]
        return np.abs(b.t - a.t) - 0.5 * (a.width_m + b.width_m)


def time_to_overlap(a, b, horizon_s: float = TTC_CAP_S) -> np.ndarray:
    """Per sample, the time [s] until the boxes of actor tracks `a` and `b` first overlap if
    both keep their velocity (speed along heading) and heading from that sample on: 0 when
    they overlap already, `horizon_s` when they do not within it (never, for two actors
    that pass each other clear).

    Exact for two rectangles moving without rotation: they overlap while their centres'
    relative position projects, on each of the four box axes, within the sum of both boxes'
    half-extents on that axis (separating axes); each axis gives the interval of times it
    holds, and the first overlap is the start of the intersection of the four."""
    ha, hb = np.asarray(a.heading, float), np.asarray(b.heading, float)
    ua, ub = np.stack([np.cos(ha), np.sin(ha)]), np.stack([np.cos(hb), np.sin(hb)])
    na, nb = np.stack([-ua[1], ua[0]]), np.stack([-ub[1], ub[0]])
    d = np.stack([np.asarray(b.x, float) - a.x, np.asarray(b.y, float) - a.y])
    v = ub * np.asarray(b.speed, float) - ua * np.asarray(a.speed, float)
    la, wa, lb, wb = 0.5 * a.length_m, 0.5 * a.width_m, 0.5 * b.length_m, 0.5 * b.width_m
    lo = np.zeros(d.shape[1])
    hi = np.full(d.shape[1], float(horizon_s))
    for e in (ua, na, ub, nb):
        def along(w):
            return np.abs(np.sum(w * e, axis=0))

        reach = la * along(ua) + wa * along(na) + lb * along(ub) + wb * along(nb)
        p, q = np.sum(d * e, axis=0), np.sum(v * e, axis=0)
        moving = np.abs(q) > 1e-9
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            t1, t2 = (-reach - p) / q, (reach - p) / q
        enter = np.where(moving, np.minimum(t1, t2), np.where(np.abs(p) <= reach, -np.inf, np.inf))
        leave = np.where(moving, np.maximum(t1, t2), np.where(np.abs(p) <= reach, np.inf, -np.inf))
        lo, hi = np.maximum(lo, enter), np.minimum(hi, leave)
    return np.where(lo <= hi, lo, float(horizon_s))


@SIGNALS.register
class Ttc(SignalFn):
    keyword = "ttc"
    args = ("actor", "actor")
    dim = units.TIME
    doc = (f"time to collision of the first actor into the second: along the road (or shared route), "
           f"the bumper gap over the closing speed when they overlap laterally and close in; between "
           f"actors on different roads or routes (or driving different ways), the time until their boxes "
           f"first overlap if both keep their velocity and heading; capped at {TTC_CAP_S:g} s, also "
           f"when they never meet [s]")

    @staticmethod
    def compute(trace, args):
        a, b = trace.actors[args[0]], trace.actors[args[1]]
        if not same_frame(a, b):
            return time_to_overlap(a, b, TTC_CAP_S)
        gap = (b.s - a.s) - 0.5 * (a.length_m + b.length_m)
        closing = a.speed - b.speed
        overlap = np.abs(a.t - b.t) < 0.5 * (a.width_m + b.width_m) + 0.2
        with np.errstate(divide="ignore", invalid="ignore"):
            ttc = np.where((closing > 1e-6) & (gap > -0.5 * a.length_m) & overlap,
                           np.maximum(gap, 0.0) / closing, TTC_CAP_S)
        return np.minimum(ttc, TTC_CAP_S)


@SIGNALS.register
class Latency(SignalFn):
    keyword = "latency"
    args = ("node",)
    dim = units.TIME
    doc = "latency of a stack node, or `e2e` from sensor timestamp to actuation [s]"

    @staticmethod
    def compute(trace, args):
        return trace.latency[args[0]]


@SIGNALS.register
class ObjectCount(SignalFn):
    keyword = "objects"
    args = ()
    dim = units.DIMENSIONLESS
    doc = "number of objects the perception reports"

    @staticmethod
    def compute(trace, args):
        return trace.object_count if trace.object_count is not None else np.zeros_like(trace.time)


# Step states recorded in `Trace.steps` (one code per sample, for each named step).
STEP_WAITING, STEP_STARTED, STEP_ENDED = 0, 1, 2


def _step_state(trace, name: str) -> np.ndarray:
    state = trace.steps.get(name)
    return np.zeros_like(trace.time) if state is None else np.asarray(state)


@SIGNALS.register
class Started(SignalFn):
    keyword = "started"
    args = ("step",)
    boolean = True
    doc = ("whether a named step has fired (started its behaviour or group), also once it ended "
           "(OpenSCENARIO StoryboardElementStateCondition, startTransition)")

    @staticmethod
    def compute(trace, args):
        return np.where(_step_state(trace, args[0]) >= STEP_STARTED, 1.0, -1.0)


@SIGNALS.register
class Ended(SignalFn):
    keyword = "ended"
    args = ("step",)
    boolean = True
    doc = ("whether a named step's behaviour has completed: a lane change in its lane, a brake at "
           "its speed, a speed profile past its last point, a group when all its steps ended "
           "(OpenSCENARIO StoryboardElementStateCondition, endTransition)")

    @staticmethod
    def compute(trace, args):
        return np.where(_step_state(trace, args[0]) >= STEP_ENDED, 1.0, -1.0)


@SIGNALS.register
class Light(SignalFn):
    keyword = "light"
    args = ("light",)
    dim = units.DIMENSIONLESS
    doc = "state of a traffic-light controller: compare with `green`, `yellow`, `red` (0, 1, 2)"

    @staticmethod
    def compute(trace, args):
        return trace.lights[args[0]]


@SIGNALS.register
class RedLight(SignalFn):
    keyword = "red_light"
    dim = units.LENGTH
    doc = ("margin to running a red light: while a light that governs the actor's lane is red, "
           "the distance of its front bumper to the stop line, negative once it crosses it (until "
           "30 m past it); 100 m when no red light is ahead within 100 m [m]")

    @staticmethod
    def compute(trace, args):
        margin = trace.red_margin.get(args[0])
        return margin if margin is not None else np.full_like(trace.time, 100.0)


def compute_signals(trace, names: set[str]) -> dict[str, np.ndarray]:
    """Evaluate canonical signal names (`ttc(ego,lead)`) on a trace."""
    out: dict[str, np.ndarray] = {}
    for name in names:
        fn, _, rest = name.partition("(")
        args = tuple(a for a in rest.rstrip(")").split(",") if a)
        cls = SIGNALS.get(fn)
        if cls is None:
            raise KeyError(f"unknown signal {name!r}")
        out[name] = np.asarray(cls.compute(trace, args), dtype=float)
    return out
