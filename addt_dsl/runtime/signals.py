"""Signal functions usable in oracles and triggers: `compute` derives each from a `Trace`
(the implementations of the specs in `addt_dsl/specs/signals.py`).
"""

from __future__ import annotations

import numpy as np

from addt_dsl.registry import SIGNALS
from addt_dsl.runtime.lights import REACH_M
from addt_dsl.specs import signals as S
from addt_dsl.specs.signals import TTC_CAP_S

def canonical(fn: str, args: tuple[str, ...]) -> str:
    return f"{fn}({','.join(args)})"


def parse(name: str) -> tuple[str, tuple[str, ...]]:
    """A canonical signal name's function and arguments (`canonical`'s inverse)."""
    fn, _, rest = name.partition("(")
    return fn, tuple(a for a in rest.rstrip(")").split(",") if a)


class SignalFn(S.SignalSpec):
    @staticmethod
    def compute(trace, args: tuple[str, ...]) -> np.ndarray:
        raise NotImplementedError


def _field_signal(field_name: str) -> type[SignalFn]:
    class _Field(S.FIELD_SPECS[field_name], SignalFn):
        @staticmethod
        def compute(trace, args):
            return getattr(trace.actors[args[0]], field_name)

    _Field.__name__ = _Field.__qualname__ = f"Signal_{field_name}"
    return SIGNALS.implements(_Field)


for _name in S.FIELD_SPECS:
    _field_signal(_name)


@SIGNALS.implements
class Jerk(S.Jerk, SignalFn):

    @staticmethod
    def compute(trace, args):
        a = trace.actors[args[0]].accel
        return np.gradient(a, trace.period_s) if len(a) > 1 else np.zeros_like(a)


@SIGNALS.implements
class Travelled(S.Travelled, SignalFn):

    @staticmethod
    def compute(trace, args):
        a = trace.actors[args[0]]
        return np.concatenate(([0.0], np.cumsum(np.hypot(np.diff(a.x), np.diff(a.y)))))


@SIGNALS.implements
class RoadEdge(S.RoadEdge, SignalFn):

    @staticmethod
    def compute(trace, args):
        return trace.road_edge[args[0]]  # (recorded for each actor a condition or oracle names)


@SIGNALS.implements
class RoadEnd(S.RoadEnd, SignalFn):

    @staticmethod
    def compute(trace, args):
        return trace.road_end[args[0]]  # (recorded for each actor a condition or oracle names)


@SIGNALS.implements
class Distance(S.Distance, SignalFn):

    @staticmethod
    def compute(trace, args):
        a, b = trace.actors[args[0]], trace.actors[args[1]]
        return np.hypot(a.x - b.x, a.y - b.y)


@SIGNALS.implements
class Gap(S.Gap, SignalFn):

    @staticmethod
    def compute(trace, args):
        a, b = trace.actors[args[0]], trace.actors[args[1]]
        if not same_frame(a, b):
            return np.hypot(a.x - b.x, a.y - b.y) - 0.5 * (a.length_m + b.length_m)
        return (b.s - a.s) - 0.5 * (a.length_m + b.length_m)


def same_frame(a, b) -> bool:
    """Whether two actor tracks measure `s` along the same road or route (`ActorTrack.frame`)."""
    return a.frame == b.frame


@SIGNALS.implements
class RelSpeed(S.RelSpeed, SignalFn):

    @staticmethod
    def compute(trace, args):
        return trace.actors[args[0]].speed - trace.actors[args[1]].speed


@SIGNALS.implements
class LatGap(S.LatGap, SignalFn):

    @staticmethod
    def compute(trace, args):
        a, b = trace.actors[args[0]], trace.actors[args[1]]
        return np.abs(b.t - a.t) - 0.5 * (a.width_m + b.width_m)


@SIGNALS.implements
class LonGap(S.LonGap, SignalFn):

    @staticmethod
    def compute(trace, args):
        # esmini's Object::CollisionAndRelativeDistLatLong on the first actor's longitudinal
        # axis: the gap between the projections of both boxes' corners on its heading.
        a, b = trace.actors[args[0]], trace.actors[args[1]]
        ha, hb = np.asarray(a.heading, float), np.asarray(b.heading, float)
        along = (np.asarray(b.x, float) - a.x) * np.cos(ha) + (np.asarray(b.y, float) - a.y) * np.sin(ha)
        reach_b = 0.5 * b.length_m * np.abs(np.cos(hb - ha)) + 0.5 * b.width_m * np.abs(np.sin(hb - ha))
        ahead = along - reach_b - 0.5 * a.length_m
        behind = along + reach_b + 0.5 * a.length_m
        return np.where(ahead > 0.0, ahead, np.where(behind < 0.0, behind, 0.0))


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


@SIGNALS.implements
class Ttc(S.Ttc, SignalFn):

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


@SIGNALS.implements
class Latency(S.Latency, SignalFn):

    @staticmethod
    def compute(trace, args):
        return trace.latency[args[0]]


@SIGNALS.implements
class ObjectCount(S.ObjectCount, SignalFn):

    @staticmethod
    def compute(trace, args):
        return trace.object_count if trace.object_count is not None else np.zeros_like(trace.time)


# Step states recorded in `Trace.steps` (one code per sample, for each named step).
STEP_WAITING, STEP_STARTED, STEP_ENDED = 0, 1, 2


def _step_state(trace, name: str) -> np.ndarray:
    state = trace.steps.get(name)
    return np.zeros_like(trace.time) if state is None else np.asarray(state)


@SIGNALS.implements
class Started(S.Started, SignalFn):

    @staticmethod
    def compute(trace, args):
        return np.where(_step_state(trace, args[0]) >= STEP_STARTED, 1.0, -1.0)


@SIGNALS.implements
class Ended(S.Ended, SignalFn):

    @staticmethod
    def compute(trace, args):
        return np.where(_step_state(trace, args[0]) >= STEP_ENDED, 1.0, -1.0)


@SIGNALS.implements
class LaneId(S.LaneId, SignalFn):

    @staticmethod
    def compute(trace, args):
        return _per_actor(trace, trace.lanes, args[0], np.nan)


@SIGNALS.implements
class WrongWay(S.WrongWay, SignalFn):

    @staticmethod
    def compute(trace, args):
        return _per_actor(trace, trace.wrong_way, args[0], -1.0)


@SIGNALS.implements
class OffLanes(S.OffLanes, SignalFn):

    @staticmethod
    def compute(trace, args):
        return _per_actor(trace, trace.off_lanes, args[0], -1.0)


@SIGNALS.implements
class Light(S.Light, SignalFn):

    @staticmethod
    def compute(trace, args):
        return trace.lights[args[0]]


@SIGNALS.implements
class Var(S.Var, SignalFn):

    @staticmethod
    def compute(trace, args):
        return trace.variables[args[0]]


@SIGNALS.implements
class RedLight(S.RedLight, SignalFn):

    @staticmethod
    def compute(trace, args):
        return _per_actor(trace, trace.red_margin, args[0], REACH_M)


@SIGNALS.implements
class StopSign(S.StopSign, SignalFn):

    @staticmethod
    def compute(trace, args):
        return _per_actor(trace, trace.stop_margin, args[0], REACH_M)


def _per_actor(trace, table: dict, actor: str, default: float) -> np.ndarray:
    """An actor's series from one of the trace's per-actor tables, recorded only for the
    actors a formula names (or where the run has lights, stop signs): `default` throughout
    where it was not recorded (no light, no sign, not on a lane)."""
    values = table.get(actor)
    return values if values is not None else np.full_like(trace.time, default)


def compute_signals(trace, names: set[str]) -> dict[str, np.ndarray]:
    """Evaluate canonical signal names (`ttc(ego,lead)`) on a trace."""
    out: dict[str, np.ndarray] = {}
    for name in names:
        fn, args = parse(name)
        if SIGNALS.get(fn) is None:
            raise KeyError(f"unknown signal {name!r}")
        cls = SIGNALS.implementation(fn)
        out[name] = np.asarray(cls.compute(trace, args), dtype=float)
    return out
