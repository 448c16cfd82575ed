"""Traffic behaviours: the implementations of the specs in `addt_dsl/specs/behaviors.py`.

A behaviour drives one longitudinal or lateral channel of a traffic agent: it returns
an acceleration command [m/s^2] and/or a lateral target (offset from the road
reference line [m]) with a smooth profile. Agents move kinematically in road
coordinates (s, t) — along the road, or at a heading relative to it (pedestrians
crossing) — so behaviours are pure Python and need no physics engine. A behaviour
that runs a manoeuvre (overtake, cross) advances its phases inside `accel`, which the
loop calls once per step.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

from addt_dsl.kernel import kernel
from addt_dsl.kernel import pow  # the C library's, as CPython's `**`
from addt_dsl.registry import BEHAVIORS
from addt_dsl.runtime.agent_arrays import AgentState
from addt_dsl.runtime.neighbours import nearest_ahead
from addt_dsl.specs import behaviors as S


def standing_yaw(agent: AgentState, yaw: float) -> float:
    """The body yaw [rad] an agent adds to its path's heading: its declared `yaw` while it
    has stood still since the start (a parked car, a waiting pedestrian); 0 from its first
    motion on, when its body follows its path (the lane, a lane change, a walk)."""
    if agent.moved:
        return 0.0
    if agent.speed > 0.0:
        agent.moved = True
        return 0.0
    return yaw


# A speed counts as reached within this [m/s] for `ended(step)` (tracking lands on it).
ENDED_SPEED_TOL_MS = 1e-3
# A lane change onto a moving lane centre samples that centre every LC_SAMPLE_M [m] over
# LC_SPAN_FACTOR times the distance it covers at its start speed plus LC_SPAN_MARGIN_M [m]
# (room to speed up; beyond it, the last centre).
LC_SAMPLE_M, LC_SPAN_FACTOR, LC_SPAN_MARGIN_M = 1.0, 2.0, 30.0


class Behavior(S.BehaviorSpec):
    def __init__(self, settings: dict):
        self.settings = {p.name: settings.get(p.name, p.default) for p in self.params}

    def start(self, agent: AgentState, world, time_s: float) -> None:
        """Called when the behaviour becomes active."""

    def value(self, name: str, world) -> float:
        """A setting's value now: a live setting (one that reads signals, e.g. `speed
        speed(ego) + 5 km/h`) is evaluated on the current state at every call."""
        v = self.settings[name]
        return v if isinstance(v, (int, float)) else world.live_value(v)

    def accel(self, agent: AgentState, world, time_s: float) -> float:
        return 0.0

    def ended(self, agent: AgentState, world, time_s: float) -> bool:
        """Whether the behaviour has completed on the state at `time_s` (what `ended(step)`
        reads). Behaviours without a natural end (car following, keeping a gap, walking)
        never end."""
        return False

    def array_law(self, world, time_s: float):
        """How the agents' kernel (`fleet.step`) steps this behaviour from `time_s` on until
        another starts: (law, settings), its `accel` being that law (`LAWS`) of the agent's
        speed (and, for IDM, its leader) and these fixed settings [SI]; `LATER` where it
        will be such a law from a later step (ask again then); None: never (its `accel`
        steps it, one agent at a time)."""
        return None


# The longitudinal laws the agents' kernel steps (`fleet.step`): one definition each, a
# kernel that behaviours' `accel` call interpreted (`.py_func`) and `fleet.step` compiled
# in. `LAW_NONE`: no acceleration (no longitudinal behaviour).
LAW_NONE, LAW_IDM, LAW_TRACK, LAW_BRAKE = range(4)
LAWS = ("none", "idm", "track", "brake")
LAW_PARAMS = 5  # the most settings of a law (IDM's, `IdmParams`)
LATER = "later"  # `array_law`: not yet


@kernel
def speed_tracking(v, target, a_max, b_max, dt):
    """Accelerate at `a_max` (brake at `b_max`) [m/s^2] from speed `v` until the `target`
    speed [m/s], landing on it within the step `dt` [s]: an acceleration setting is the
    acceleration the agent has. (A first-order lag here once gave 1.32 m/s after 3 s at
    `accel 2 m/s^2`.) `max(-b_max, min(a_max, x))` written as Python's `min` and `max` pick."""
    x = (target - v) / dt
    x = x if x < a_max else a_max
    return x if x > -b_max else -b_max


@kernel
def brake_accel(v, decel, to_speed, dt):
    """Brake at `decel` [m/s^2] from speed `v`, landing on `to_speed` [m/s] instead of
    overshooting below it within the step `dt` [s]; never speeding up. `min(0.0,
    max(-decel, x))` written as Python's `min` and `max` pick."""
    x = (to_speed - v) / dt
    x = x if x > -decel else -decel
    return x if x < 0.0 else 0.0


def _speed_tracking(agent: AgentState, target: float, a_max: float, b_max: float, dt: float) -> float:
    """`speed_tracking` of the agent's speed."""
    return speed_tracking.py_func(agent.speed, target, a_max, b_max, dt)


def _fixed(*values) -> bool:
    """Whether settings are numbers (not live expressions read at each step)."""
    return all(isinstance(v, (int, float)) for v in values)


# Dynamics shapes (OpenSCENARIO TransitionDynamics): progress u in [0, 1] -> blend in
# [0, 1]. `quintic` (zero speed and acceleration at both ends) is the lane changes'
# default; OpenSCENARIO's cubic is 3u^2 - 2u^3, its sinusoidal (1 - cos(pi u)) / 2.
SHAPES = {
    "step": lambda u: 1.0,
    "linear": lambda u: u,
    "cubic": lambda u: u * u * (3.0 - 2.0 * u),
    "sinusoidal": lambda u: 0.5 * (1.0 - math.cos(math.pi * u)),
    "quintic": lambda u: u * u * u * (10.0 - 15.0 * u + 6.0 * u * u),
}
# Peak slope of each blend relative to the linear one (max d blend / du): a rate limit
# [m/s^2] turns into the duration that keeps the shape's peak within it.
PEAK_SLOPE = {"step": 0.0, "linear": 1.0, "cubic": 1.5, "sinusoidal": math.pi / 2, "quintic": 1.875}
assert tuple(SHAPES) == S.SHAPES and set(S.SPEED_SHAPES) <= set(SHAPES)  # the spec names these


def blend(shape: str, u: float) -> float:
    return SHAPES[shape](min(1.0, max(0.0, u)))


class SpeedTransition:
    """A speed change from `v0` to `v1` with a dynamics shape, starting at `start_s`.

    `duration_s` when given; otherwise as long as it takes for the shape's peak
    acceleration to equal the rate limit (`accel` speeding up, `decel` slowing down)."""

    def __init__(self, v0: float, v1: float, start_s: float, shape: str, accel: float, decel: float,
                 duration_s: float | None = None):
        self.v0, self.v1, self.start_s, self.shape = v0, v1, start_s, shape
        rate = accel if v1 >= v0 else decel
        if shape == "step":
            self.duration_s = 0.0
        elif duration_s is not None:
            self.duration_s = duration_s
        else:
            self.duration_s = PEAK_SLOPE[shape] * abs(v1 - v0) / rate if rate > 0 else math.inf

    def speed_at(self, time_s: float) -> float:
        if self.duration_s <= 0.0 or not math.isfinite(self.duration_s):
            return self.v1 if self.duration_s <= 0.0 else self.v0
        return self.v0 + (self.v1 - self.v0) * blend(self.shape, (time_s - self.start_s) / self.duration_s)

    def active(self, time_s: float, dt: float) -> bool:
        """Whether the change is still under way at `time_s` (a step change takes one step)."""
        return time_s < self.start_s + max(self.duration_s, dt) - 1e-9

    def accel(self, agent: AgentState, time_s: float, dt: float) -> float:
        """The acceleration that puts the agent on the profile at the end of this step."""
        return (self.speed_at(time_s + dt) - agent.speed) / dt




def distance_duration(v0: float, v1: float, distance: float) -> float:
    """The time [s] of a speed change from `v0` to `v1` [m/s] over `distance` [m], as esmini
    converts it (LongSpeedAction::Start): 2 d / |v0 + v1|, the mean speed of a symmetric
    shape; through standstill, each part's share of the distance in proportion to its v^2;
    no change in speed: at once."""
    if abs(v1 - v0) < _SMALL:
        return 0.0
    if abs(v0) > _SMALL and abs(v1) > _SMALL and (v0 > 0) != (v1 > 0):
        d0 = distance * v0 * v0 / (v0 * v0 + v1 * v1)
        return 2.0 * d0 / abs(v0) + 2.0 * (distance - d0) / abs(v1)
    return 2.0 * distance / abs(v0 + v1)


@BEHAVIORS.implements
class Cruise(S.Cruise, Behavior):
    transition: SpeedTransition | None = None  # a shaped or timed change, set by start()

    def start(self, agent, world, time_s):
        s = self.settings
        self.transition = None
        if s["shape"] != "linear" or s["duration"] is not None or s["distance"] is not None:
            # A live target is taken as it is at the start; it is followed once reached.
            v1 = max(0.0, self.value("speed", world))
            duration = s["duration"]
            if s["distance"] is not None:
                duration = distance_duration(agent.speed, v1, s["distance"])
            bound = s.get("max_accel") if v1 >= agent.speed else s.get("max_decel")
            if duration is not None and bound and s["shape"] in PEAK_SLOPE:
                # esmini (TransitionDynamics::SetMaxRate): the time scaled so the peak is the bound
                duration = max(duration, PEAK_SLOPE[s["shape"]] * abs(v1 - agent.speed) / bound)
            accel, decel = self.rates()
            self.transition = SpeedTransition(agent.speed, v1, time_s, s["shape"], accel, decel, duration)

    def rates(self) -> tuple[float, float]:
        """The rate limits [m/s^2], each within the vehicle's bound where one is set (at a rate
        the Performance caps the peak as it stretches a change over a time)."""
        s = self.settings
        return (min(s["accel"], s.get("max_accel") or math.inf),
                min(s["decel"], s.get("max_decel") or math.inf))

    def accel(self, agent, world, time_s):
        tr = self.transition
        if tr is not None and tr.active(time_s, world.dt):
            return tr.accel(agent, time_s, world.dt)
        # Linear at the rate limits: the same as tracking the target.
        return _speed_tracking(agent, max(0.0, self.value("speed", world)), *self.rates(), world.dt)

    def array_law(self, world, time_s):
        # Tracking a fixed target once a shaped or timed change is over.
        speed = self.settings["speed"]
        if not _fixed(speed):
            return None
        tr = self.transition
        if tr is not None and tr.active(time_s, world.dt):
            return LATER
        return LAW_TRACK, (max(0.0, speed), *self.rates())

    def ended(self, agent, world, time_s):
        # At the target speed: the shaped change is over, or the speed is on the target.
        if self.transition is not None:
            return not self.transition.active(time_s, world.dt)
        return abs(agent.speed - max(0.0, self.value("speed", world))) < ENDED_SPEED_TOL_MS


# esmini's numeric tolerance and its "unlimited" (CommonMini.hpp SMALL_NUMBER, LARGE_NUMBER).
_SMALL, _LARGE = 1e-6, 1e10


@dataclass
class ProfileSegment:
    """A piece of a planned speed profile from `t` [s]: v + k (τ - t) + j (τ - t)² / 2 [m/s]."""

    t: float
    v: float
    k: float  # acceleration at `t` [m/s^2]
    j: float  # jerk [m/s^3]

    def speed_at(self, time_s: float) -> float:
        d = time_s - self.t
        return self.v + self.k * d + 0.5 * self.j * d * d


def follow_profile(t0: float, v0: float, a0: float, deltas: list[float], speeds: list[float],
                   accel: float, decel: float, accel_rate: float, decel_rate: float, max_speed: float,
                   follow: bool = True) -> list[ProfileSegment]:
    """esmini 3.6's plan of a SpeedProfileAction (LongSpeedProfileAction::Start), started at
    `t0` [s] at speed `v0` [m/s] and acceleration `a0` [m/s^2]; `deltas[i]` [s] is entry i's
    time after the previous one (OpenSCENARIO's convention), `speeds[i]` its speed.

    The entries become vertices joined by straight lines (a slope beyond `accel`/`decel` is
    cut to it and its entry comes later; a vertex on the line of the previous two is dropped).
    In follow mode the plan keeps each line's slope and joins consecutive lines with a jerk
    segment at `accel_rate` (speeding up) or `decel_rate`, placed so that it leaves the first
    line and lands on the second; a single target is reached with two jerk segments and,
    where time allows, a line between. A corner that cannot be placed, or a segment beyond a
    limit, turns the rest of the plan into straight lines through the vertices (esmini's
    fallback to position mode), as esmini does. Limits: `_LARGE` for unlimited."""
    mode = {"follow": follow}

    def check(v: float, k: float, j: float) -> None:  # esmini's CheckSpeed/Acceleration/Rate
        if mode["follow"] and (abs(v) > max_speed + _SMALL or k > accel + _SMALL or k < -decel - _SMALL
                               or j > accel_rate + _SMALL or j < -decel_rate - _SMALL):
            mode["follow"] = False

    segments: list[ProfileSegment] = []

    def add(t: float, v: float, k: float, j: float) -> None:
        check(v, k, j)
        segments.append(ProfileSegment(t, v, k, j))

    # Vertices [t, v, k, m]: time, speed, slope of the line to the next, its intercept v - k t
    # (esmini's EntryVertex: without a slope, both 0).
    def vertex(t, v, k=None):
        return [t, v, 0.0, 0.0] if k is None else [t, v, k, v - k * t]
    n = len(deltas)
    index = 0
    if deltas[0] > _SMALL:
        vertices = [vertex(t0, v0)]
    elif follow:  # a first entry at 0 is replaced by the current speed
        vertices, index = [vertex(t0, v0)], 1
    else:
        vertices = [vertex(t0, speeds[0])]
    time = t0
    for index in range(index, n):
        dt = deltas[index]
        dv = speeds[index] - vertices[-1][1]
        k = dv / dt if dt else (math.copysign(math.inf, dv) if dv else math.nan)  # C++'s division
        if k < -decel or k > accel:  # beyond the limits: at the limit, the entry comes later
            if abs(dv) < _SMALL:
                continue
            k = max(k, -decel) if k < 0 else min(k, accel)
            vertices[-1][0] = time
            time += dv / k
        else:
            time += dt
        if index < n - 1 and dt < _SMALL:
            vertices[-1] = vertex(time, speeds[index])
            continue
        last = vertices[-1]
        last[2], last[3] = k, last[1] - k * last[0]
        delta_k = last[2] - (vertices[-2][2] if index > 1 else a0)
        if abs(delta_k) < _SMALL and index > 1:
            prev = vertices[-2]
            vertices[-1] = vertex(time, speeds[index], (speeds[index] - prev[1]) / (time - prev[0]))
            continue
        vertices.append(vertex(time, speeds[index], 0.0) if index == n - 1 else vertex(time, speeds[index]))

    if len(vertices) == 1:
        add(vertices[0][0], vertices[0][1], 0.0, 0.0)
    elif follow and len(vertices) == 2:
        _follow_single_target(vertices, a0, accel, decel, accel_rate, decel_rate, add)
    else:
        k1, m1, t3 = 0.0, 0.0, vertices[0][0]
        if follow:
            t, v, k, _ = vertices[0]
            j = 0.0
            if abs(k) > _SMALL:
                j = -decel_rate if k - a0 < 0 else accel_rate
                add(t, v, a0, j)
                t3 = t + ((k - a0) / j if abs(j) > _SMALL else 0.0)
            v3 = v + a0 * (t3 - t0) + 0.5 * j * (t3 - t0) ** 2  # speed after the first jerk
            k1, m1 = k, v3 - k * t3
            add(t3, v3, k1, 0.0)
        for index in range(len(vertices)):
            if not mode["follow"]:
                t, v, k, _ = vertices[index]
                add(t, v, k, 0.0)
            elif index < len(vertices) - 1:
                k0, t0_, v0_, m0 = k1, t3, v3, m1
                _, _, k1, m1 = vertices[index + 1]
                j = -decel_rate if k1 - k0 < 0 else accel_rate
                if abs(k0 - k1) >= _SMALL:
                    # The jerk segment from line (k0, m0) at t1 onto line (k1, m1) at t3.
                    t1 = (k0 * k0 - 2 * k0 * k1 + k1 * k1 - 2 * j * (m0 - m1)) / (2 * j * (k0 - k1))
                    if t1 < t0_:
                        mode["follow"] = False
                        continue
                    v1 = v0_ + k0 * (t1 - t0_)
                    t3 = t1 + (k1 - k0) / j
                    v3 = v1 + k0 * (t3 - t1) + 0.5 * j * (t3 - t1) ** 2
                    add(t1, v1, k0, j)
                add(t3, v3, k1, 0.0)
    return segments


def _follow_single_target(vertices, k0, accel, decel, accel_rate, decel_rate, add) -> None:
    """esmini's follow mode for one target: jerk away from the current acceleration `k0`,
    a line where time allows, jerk back to zero acceleration on the target speed; beyond
    the acceleration limits, a line at the limit and a later arrival."""
    t0, v0, k_first, _ = vertices[0]
    t3, v3 = vertices[1][0], vertices[1][1]
    j0 = -decel_rate if k_first - k0 < 0 else accel_rate
    add(t0, v0, k0, j0)
    j1 = accel_rate if k_first < 0 else -decel_rate
    t1 = t2 = v2 = k1 = 0.0  # esmini's values where it finds no solution

    def in_span(k):
        return -decel <= k <= accel
    if abs(j1 - j0) < _SMALL:
        if abs(t0 - t3) > _SMALL and abs(j1 * (t0 - t3) - k0) > _SMALL:
            t1 = ((2 * j1 * (v0 + t0 * j1 * (t0 - t3) - v3) + k0 ** 2 + 2 * k0 * j1 * (t3 - 2 * t0))
                  / (2 * j1 * (j1 * (t0 - t3) - k0)))
            if t1 >= 0:
                v1 = v0 + k0 * (t1 - t0) + j0 * 0.5 * (t1 - t0) ** 2
                k1 = k0 + j0 * (t1 - t0)
                t2 = k1 / j1 + t3
                if t2 >= 0:
                    v2 = v1 + k1 * (t2 - t1)
                    if -decel < k1 < accel:
                        add(t1, v1, k1, 0.0)
    else:
        factor = j0 * j1 * (2 * v0 * (j1 - j0) + k0 ** 2 + 2 * k0 * j1 * (t3 - t0) + j0 * j1 * (t0 - t3) ** 2
                            + 2 * v3 * (j0 - j1))
        if factor < 0.0:  # no time for a line: the two jerk segments meet
            t2 = ((math.sqrt(j1 * (-(j0 - j1)) * (j0 * (2 * v3 - 2 * v0) + k0 ** 2)) + (j0 - j1) * (t0 * j0 - k0))
                  / (j0 * (j0 - j1)))
            v2 = v0 + k0 * (t2 - t0) + j0 * 0.5 * (t2 - t0) ** 2
            k1 = k0 + j0 * (t2 - t0)
            t3 = t2 - k1 / j1
        else:  # a line to reach the speed on time
            t1 = (-math.sqrt(factor) - j0 * (k0 + t3 * j1) + t0 * j0 ** 2) / (j0 * (j0 - j1))
            v1 = v0 + k0 * (t1 - t0) + j0 * 0.5 * (t1 - t0) ** 2
            k1 = k0 + j0 * (t1 - t0)
            t2 = k1 / j1 + t3
            v2 = v1 + k1 * (t2 - t1)
            if in_span(k1):
                add(t1, v1, k1, 0.0)
    if in_span(k1):
        add(t2, v2, k1, j1)
        add(t3, v3, 0.0, 0.0)
        return
    k1 = min(max(k1, -decel), accel)  # at the limit: arrive later
    t1 = t0 + (k1 - k0) / j0
    v1 = v0 + k0 * (t1 - t0) + 0.5 * j0 * (t1 - t0) ** 2
    t2 = (v3 - v1) / k1 + t1 + k1 / (2 * j1)
    v2 = v3 + k1 ** 2 / (2 * j1)
    t3 = -v1 / k1 + v3 / k1 + t1 - k1 / (2 * j1)
    add(t1, v1, k1, 0.0)
    add(t2, v2, k1, j1)
    add(t3, v3, 0.0, 0.0)


@BEHAVIORS.implements
class SpeedProfile(S.SpeedProfile, Behavior):
    plan: list[ProfileSegment] | None = None  # mode follow's segments, set by start()

    def start(self, agent, world, time_s):
        self.plan = None
        if self.settings["mode"] == "follow":
            times = list(self.settings["times"])
            deltas = [times[0]] + [b - a for a, b in zip(times, times[1:])]
            limits = [_LARGE if self.settings[n] is None else self.settings[n] for n in self.FOLLOW_LIMITS]
            self.plan = follow_profile(time_s, agent.speed, agent.accel, deltas, list(self.settings["speeds"]),
                                       *limits)
            self.end_s = self.plan[-1].t
            return
        times = [time_s + t for t in self.settings["times"]]
        speeds = list(self.settings["speeds"])
        if times[0] > time_s:  # from the current speed to the first point
            times, speeds = [time_s] + times, [agent.speed] + speeds
        shape = self.settings["shape"]
        # A step shape jumps at each point's time; the others blend towards it.
        self.segments = [SpeedTransition(v0, v1, t1 if shape == "step" else t0, shape, 0.0, 0.0, t1 - t0)
                         for t0, t1, v0, v1 in zip(times, times[1:], speeds, speeds[1:])]
        self.first_speed = speeds[0]
        self.end_s = times[-1]

    def ended(self, agent, world, time_s):
        return time_s + 1e-9 >= self.end_s  # at the last point

    def speed_at(self, time_s: float) -> float:
        """The profile's speed [m/s] at `time_s`: on the segment begun last."""
        if self.plan is not None:  # the plan's last segment holds its speed (esmini stops there)
            seg = self.plan[0]
            for nxt in self.plan[1:]:
                if time_s <= nxt.t - _SMALL:
                    break
                seg = nxt
            return 0.0 if abs(v := seg.speed_at(time_s)) < _SMALL else v
        v = self.first_speed
        for seg in self.segments:
            if time_s + 1e-9 < seg.start_s:
                break
            v = seg.speed_at(time_s)
        return v

    def accel(self, agent, world, time_s):
        # Put the agent on the profile at the end of the step (a first point at the
        # start sets the speed in one step).
        return (self.speed_at(time_s + world.dt) - agent.speed) / world.dt


@BEHAVIORS.implements
class Idm(S.Idm, Behavior):

    def accel(self, agent, world, time_s):
        p = self._params
        if p is None:
            p = self._params = IdmParams.of(self.settings)
        free = idm_free.py_func(agent.speed, p.v0)
        lead = world.leader_of(agent)
        if lead is None:
            return p.accel * free
        return idm_accel.py_func(agent.speed, free, *lead, p.accel, p.time_gap, p.min_gap, p.two_sqrt_ab)

    def array_law(self, world, time_s):
        if not _fixed(*self.settings.values()):
            return None
        p = IdmParams.of(self.settings)
        return LAW_IDM, (p.v0, p.accel, p.time_gap, p.min_gap, p.two_sqrt_ab)

    _params = None


class IdmParams:
    """IDM settings with their per-agent constants (`Idm.array_law`'s settings, in this order)."""

    def __init__(self, v0, accel, time_gap, min_gap, two_sqrt_ab):
        self.v0, self.accel, self.time_gap, self.min_gap, self.two_sqrt_ab = v0, accel, time_gap, min_gap, two_sqrt_ab

    @classmethod
    def of(cls, p: dict) -> IdmParams:
        return cls(max(p["speed"], 0.1), p["accel"], p["time_gap"], p["min_gap"],
                   2.0 * math.sqrt(p["accel"] * p["decel"]))


# IDM's formulas, one definition: interpreted (`.py_func`) by `Idm`, compiled into the
# agents' kernel (`fleet.step`); powers by the C library's pow (`kernel.pow`), as Python's.
@kernel
def idm_free(v, v0):
    """The free-road term `1 - (v / v0) ** 4` of IDM."""
    return 1.0 - pow(v / v0, 4.0)


@kernel
def idm_accel(v, free, gap, lead_speed, accel, time_gap, min_gap, two_sqrt_ab):
    """IDM's acceleration [m/s^2] behind a leader `gap` [m] ahead at `lead_speed` [m/s]
    (`free`: `idm_free`). `max(0.0, x)` and `max(gap, 0.1)` written as Python's `max` picks."""
    dv = v - lead_speed
    x = v * time_gap + v * dv / two_sqrt_ab
    s_star = min_gap + (x if x > 0.0 else 0.0)
    return accel * (free - pow(s_star / (0.1 if 0.1 > gap else gap), 2.0))


@BEHAVIORS.implements
class KeepGap(S.KeepGap, Behavior):
    SPRING_PER_ACCEL = 0.4  # stiffness [1/s^2] per m/s^2 of the acceleration limit (esmini's)

    def accel(self, agent, world, time_s):
        s = self.settings
        other = world.actor_station(s["target"])
        if other is None:
            return 0.0
        o_s, o_speed, o_length = other
        sign = 1.0 if s["side"] == "behind" else -1.0
        # Signed bumper-to-bumper distance to the target (positive: it is ahead) and the one
        # wanted: `sign * want`.
        distance = (o_s - agent.s) - sign * 0.5 * (agent.length_m + o_length)
        want = s["distance"] if s["distance"] is not None else s["time_gap"] * abs(o_speed)
        error = distance - sign * want
        stiffness = self.SPRING_PER_ACCEL * (s["accel"] if error < 0.0 else s["decel"])
        a = error * stiffness - (agent.speed - o_speed) * 2.0 * math.sqrt(stiffness)
        return max(-s["decel"], min(s["accel"], a))


# esmini's SynchronizeAction with a final speed (OSCPrivateAction.cpp, SynchronizeAction::Step):
# its phases, its "no time left" and "master standing" sentinels and its hardest braking.
SYNC_NONE, SYNC_NON_LINEAR, SYNC_LINEAR, SYNC_STOPPED, SYNC_STOP_NOW, SYNC_WAITING = range(6)
SYNC_SMALL = 1e-6
SYNC_LARGE = 1e10
SYNC_MAX_DECEL = 8.0  # [m/s^2]


@BEHAVIORS.implements
class Synchronize(S.Synchronize, Behavior):

    def start(self, agent, world, time_s):
        if self.settings["heading"] is not None:
            _walk_towards(agent, self.settings["heading"])
        self.final = None
        self.mode = SYNC_NONE
        self.convex = False
        self.last_m = self.last_master_m = SYNC_LARGE

    def remaining_m(self, agent: AgentState) -> float:
        """Distance to the own target point along the direction of motion [m]."""
        s = self.settings
        d = 0.0
        if s["target_s"] is not None:
            d += (s["target_s"] - agent.s) * math.cos(agent.heading_rel)
        if s["target_t"] is not None:
            d += (s["target_t"] - agent.t) * math.sin(agent.heading_rel)
        return d

    def accel(self, agent, world, time_s):
        s = self.settings
        if s["final_speed"] is not None:
            return (self.profile_speed(agent, world) - agent.speed) / world.dt
        master = world.actor_station(s["master"])
        to_go = s["master_at"] - master[0] if master is not None else 0.0
        if self.final is None and (to_go <= s["master_tolerance"] or
                                   abs(self.remaining_m(agent)) <= s["tolerance"]):
            self.final = agent.speed  # the master has arrived: synchronisation ends
        if self.final is not None:
            return _speed_tracking(agent, self.final, s["accel"], s["decel"], world.dt)
        arrival_s = to_go / master[1] if master[1] > 1e-3 else math.inf
        wanted = max(0.0, self.remaining_m(agent)) / arrival_s
        return _speed_tracking(agent, min(wanted, s["max_speed"]), s["accel"], s["decel"], world.dt)

    def profile_speed(self, agent, world) -> float:
        """The speed [m/s] for this step with a final speed, as esmini plans it: the speed
        profile that reaches the final speed at the target just when the master reaches its
        point - one constant acceleration where that fits (linear), else two phases that
        first speed up and then slow down or the reverse (convex/concave), or a stop and a
        wait when even that would need moving backwards. Ends (holding the final speed) when
        either is within its tolerance of its point or has passed it."""
        s, dt = self.settings, world.dt
        if self.final is not None:
            return self.final
        master = world.actor_station(s["master"])
        to_go = s["master_at"] - master[0] if master is not None else 0.0
        master_m, dist = abs(to_go), abs(self.remaining_m(agent))
        done = (dist < s["tolerance"] + SYNC_SMALL or master_m < s["master_tolerance"] + SYNC_SMALL
                or dist > self.last_m or master_m > self.last_master_m)
        self.last_m, self.last_master_m = dist, master_m
        dist = max(dist - s["tolerance"], SYNC_SMALL)
        master_m = max(master_m - s["master_tolerance"], SYNC_SMALL)
        v_master = (master[1] if master is not None else 0.0) * (1.0 if to_go >= 0.0 else -1.0)
        speed = agent.speed
        time_left = SYNC_LARGE  # the master's time to its point [s]
        if v_master > SYNC_SMALL:
            time_left = master_m / v_master
            done = done or time_left < dt
        elif self.mode != SYNC_WAITING:
            self.mode, speed = SYNC_WAITING, 0.0  # the master stands: so does it
        v1 = self.value("final_speed", world)
        if done:
            self.final = v1
            return v1
        if self.mode == SYNC_WAITING:
            if time_left >= SYNC_LARGE:
                return speed
            self.mode = SYNC_NONE
        if self.mode == SYNC_STOP_NOW:
            speed -= SYNC_MAX_DECEL * dt
            if speed < 0.0:
                self.mode, speed = SYNC_WAITING, 0.0
            return speed
        if self.mode == SYNC_STOPPED:
            if v1 > 0.0 and time_left < 2.0 * dist / v1 or v1 <= 0.0 and time_left < SYNC_LARGE:
                self.mode = SYNC_LINEAR  # time to move again
            else:
                return 0.0
        if self.mode == SYNC_LINEAR:
            if time_left > SYNC_LARGE - 1.0:
                return 0.0
            return max(0.0, 2.0 * dist / time_left - max(0.0, v1)) if time_left >= 1e-3 and dist >= 1e-3 else 0.0
        if self.mode == SYNC_NON_LINEAR and time_left < SYNC_LARGE:
            if abs(speed - (2.0 * dist / time_left - v1)) < 0.1:
                self.mode = SYNC_LINEAR  # on the straight line to the end: past the apex
                return speed
        if self.mode == SYNC_NONE:
            self.mode = SYNC_NON_LINEAR
            self.convex = (v1 + speed) / 2.0 < dist / time_left
        # Two phases of constant acceleration meeting at speed vx after x seconds.
        t, v0, vx, acc = time_left, speed, 0.0, 0.0
        if abs(v1 - v0) < SYNC_SMALL:
            vx = (dist - t / 2.0 * v0) / (t / 2.0)
            acc = (vx - v0) / (t / 2.0)
        else:
            root = math.sqrt(2.0) * math.sqrt(max(0.0, 2.0 * dist * dist - 2.0 * (v1 + v0) * t * dist
                                                  + (v1 * v1 + v0 * v0) * t * t))
            x1 = -(root + 2.0 * dist - 2.0 * v1 * t) / (2.0 * (v1 - v0))
            x2 = -(-root + 2.0 * dist - 2.0 * v1 * t) / (2.0 * (v1 - v0))
            if 0.0 < x1 < t:
                vx = (2.0 * dist - root) / (2.0 * t)
                acc = (vx - v0) / x1
            elif 0.0 < x2 < t:
                vx = (2.0 * dist + root) / (2.0 * t)
                acc = (vx - v0) / x2
        if self.mode == SYNC_NON_LINEAR and (acc < 0.0 if self.convex else acc > 0.0):
            self.mode, acc = SYNC_LINEAR, 0.0  # the apex: keep the speed for this step
        if self.mode == SYNC_NON_LINEAR and vx < 0.0:
            # Slowing to a stop, waiting and starting again: brake over the share of the
            # distance the current speed stands for; at once if that takes over half of it.
            t1 = 2.0 * v0 * dist / (v0 * v0 + v1 * v1) if v0 or v1 else 0.0
            acc = -v0 / t1 if abs(t1) > SYNC_SMALL else 0.0
            if t1 * v0 / 2.0 > dist / 2.0:
                self.mode, acc = SYNC_STOP_NOW, -SYNC_MAX_DECEL
            if v0 + acc * dt < 0.0:
                self.mode = SYNC_STOPPED
                return 0.0
        return speed + acc * dt

    def ended(self, agent, world, time_s):
        return self.final is not None  # the master (or it) has arrived


@BEHAVIORS.implements
class Trajectory(S.Trajectory, Behavior):

    def ended(self, agent, world, time_s):
        return self.index == len(self.points)  # the last waypoint passed

    def start(self, agent, world, time_s):
        st = self.settings
        if st["s"] is not None:  # OpenDRIVE road coordinates, whichever way the agent drives
            self.points = [world.from_road_coords(agent, ps, pt) for ps, pt in zip(st["s"], st["t"])]
        else:
            self.points = [world.road_coords(agent, x, y) for x, y in zip(st["x"], st["y"])]
        self.times = [time_s + t for t in st["times"]] if st["times"] is not None else None
        self.index = 0
        self.origin = (agent.s, agent.t)
        self.last_speed = agent.speed
        # OpenSCENARIO: a trajectory without timing is driven at the speed the entity has.
        self.cruise = st["speed"] if st["speed"] is not None else agent.speed

    def accel(self, agent, world, time_s):
        st = self.settings
        while self.index < len(self.points) and self._passed(agent, time_s):
            self.origin = self.points[self.index]
            self.index += 1
        if self.index == len(self.points):  # done: on along the road at this offset
            if agent.heading_rel:
                _walk_towards(agent, 0.0)
            if self.times is not None:  # at the speed of its last segment (0 after a wait)
                return (self.last_speed - agent.speed) / world.dt
            target = agent.speed
        else:
            ps, pt = self.points[self.index]
            if (ps, pt) != (agent.s, agent.t):
                agent.heading_rel = math.atan2(pt - agent.t, ps - agent.s)
            agent.t_target, agent.lc_duration_s = agent.t, 0.0
            if self.times is None:
                target = self.cruise
            else:
                # Timed (OpenSCENARIO's position following): the remaining segment over the
                # time left to its waypoint, whatever the acceleration: it is there on time.
                left_s = self.times[self.index] - time_s
                dist = math.hypot(ps - agent.s, pt - agent.t)
                target = min(st["max_speed"], dist / left_s) if left_s > world.dt else \
                    min(st["max_speed"], dist / world.dt)
                self.last_speed = target
                return (target - agent.speed) / world.dt
        return _speed_tracking(agent, target, st["accel"], st["decel"], world.dt)

    def _passed(self, agent: AgentState, time_s: float) -> bool:
        """Whether the agent is at or beyond the current waypoint along its segment (a
        waypoint where it already is, with a time: once that time has come: it waits)."""
        (s0, t0), (s1, t1) = self.origin, self.points[self.index]
        ds, dt_ = s1 - s0, t1 - t0
        if ds * ds + dt_ * dt_ < 1e-12 and self.times is not None:
            return time_s + 1e-9 >= self.times[self.index]
        return (agent.s - s0) * ds + (agent.t - t0) * dt_ >= ds * ds + dt_ * dt_ - 1e-9


@BEHAVIORS.implements
class Brake(S.Brake, Behavior):

    def accel(self, agent, world, time_s):
        return brake_accel.py_func(agent.speed, self.settings["decel"], self.settings["to_speed"], world.dt)

    def array_law(self, world, time_s):
        s = self.settings
        return (LAW_BRAKE, (s["decel"], s["to_speed"])) if _fixed(s["decel"], s["to_speed"]) else None

    def ended(self, agent, world, time_s):
        return agent.speed <= self.settings["to_speed"] + ENDED_SPEED_TOL_MS


@BEHAVIORS.implements
class LaneChange(S.LaneChange, Behavior):

    def start(self, agent, world, time_s):
        other = self.settings["to_lane_of"]
        lane = world.actor_lane(other) if other else int(round(self.settings["to"]))
        if lane is None:  # the other actor is off the lanes: keep to the current one
            lane = agent.lane
        elif other and self.settings.get("lanes"):
            lane = S.lanes_over(lane, int(round(self.settings["lanes"])))
        begin_lane_change(agent, world, lane, self.settings["duration"], time_s, self.settings["shape"])
        self.move = (agent.lc_start_s, agent.lc_duration_s)

    def ended(self, agent, world, time_s):
        # In the target lane; a later lateral move replacing this one means it never ends.
        start, duration = self.move
        return (agent.lc_start_s, agent.lc_duration_s) == self.move and time_s + 1e-9 >= start + duration




def duration_for_peak_accel(shape: str, change_m: float, accel: float) -> float:
    """Time [s] a lateral move of `change_m` [m] with `shape` takes when its peak lateral
    acceleration is `accel` [m/s^2]; 0 for `step`."""
    if shape == "step":
        return 0.0
    return math.sqrt(S.PEAK_CURVATURE[shape] * abs(change_m) / accel)


@BEHAVIORS.implements
class LaneOffset(S.LaneOffset, Behavior):

    def start(self, agent, world, time_s):
        s = self.settings
        centre = world.lane_t(agent.road, agent.lane, agent.s)
        if math.isnan(centre):  # its lane ends here: the offset counts from where it is
            centre = agent.t
        target = centre + s["to"]
        duration = s["duration"] if s["duration"] is not None else \
            duration_for_peak_accel(s["shape"], target - agent.t, s["max_lat_accel"])
        agent.lc_shape, agent.lc_keeps_station = s["shape"], True
        agent.heading_rel = 0.0
        agent.t_start, agent.t_target = agent.t, target
        agent.lc_start_s = time_s
        agent.lc_duration_s = 0.0 if s["shape"] == "step" else duration
        self.move = (agent.lc_start_s, agent.lc_duration_s)

    def ended(self, agent, world, time_s):
        # At the offset; a later lateral move replacing this one means it never ends.
        start, duration = self.move
        return (agent.lc_start_s, agent.lc_duration_s) == self.move and time_s + 1e-9 >= start + duration


@BEHAVIORS.implements
class Teleport(S.Teleport, Behavior):

    def start(self, agent, world, time_s):
        s, t = world.from_road_coords(agent, self.settings["s"], self.settings["t"])
        agent.s, agent.t = s, t
        agent.t_target, agent.t_start, agent.lc_duration_s, agent.heading_rel = t, t, 0.0, 0.0
        agent.placed = True
        lane = world.actor_lane(agent.name)
        if lane is not None:
            agent.lane = lane

    def ended(self, agent, world, time_s):
        return True


@BEHAVIORS.implements
class CutIn(S.CutIn, LaneChange):
    pass


@BEHAVIORS.implements
class Overtake(S.Overtake, Behavior):

    def start(self, agent, world, time_s):
        self.home = agent.lane
        lane = int(round(self.settings["lane"])) or _lane_to_the_left(agent.lane)
        self.target = self.settings["target"] or _nearest_ahead(agent, world)
        self.phase = "pass"
        if math.isnan(world.lane_t(agent.road, lane, agent.s)):
            self.phase = "done"  # no passing lane here: just hold the speed
            return
        begin_lane_change(agent, world, lane, self.settings["duration"], time_s)

    def accel(self, agent, world, time_s):
        s = self.settings
        if self.phase == "pass":
            other = world.actor_station(self.target) if self.target else None
            clear = other is None or agent.s - other[0] > s["margin"] + 0.5 * (agent.length_m + other[2])
            changing = time_s < agent.lc_start_s + agent.lc_duration_s
            if clear and not changing:
                begin_lane_change(agent, world, self.home, s["duration"], time_s)
                self.phase = "done"
        return _speed_tracking(agent, s["speed"], s["accel"], s["decel"], world.dt)

    def ended(self, agent, world, time_s):
        # Back in its lane after passing (or holding the speed where it had no passing lane).
        return self.phase == "done" and time_s + 1e-9 >= agent.lc_start_s + agent.lc_duration_s


@BEHAVIORS.implements
class Walk(S.Walk, Behavior):

    def start(self, agent, world, time_s):
        _walk_towards(agent, self.settings["heading"])
        self.origin = (agent.s, agent.t, time_s)

    def accel(self, agent, world, time_s):
        s = self.settings
        return _speed_tracking(agent, s["speed"], s["accel"], s["decel"], world.dt)

    def array_law(self, world, time_s):
        # (along its lane: heading 0; `Fleet.array_plan` leaves walkers at an angle to the loop)
        s = self.settings
        return (LAW_TRACK, (s["speed"], s["accel"], s["decel"])) if _fixed(s["speed"], s["accel"], s["decel"]) \
            else None

    def ended(self, agent, world, time_s):
        # After its distance (ground: station steps times the ground scale) or its time;
        # neither set: never.
        s, (s0, t0, start) = self.settings, self.origin
        if s["distance"] is not None and \
                math.hypot((agent.s - s0) * agent.ground_scale, agent.t - t0) + 1e-9 >= s["distance"]:
            return True
        return s["duration"] is not None and time_s + 1e-9 >= start + s["duration"]


@BEHAVIORS.implements
class Cross(S.Cross, Behavior):

    def start(self, agent, world, time_s):
        left = self.settings["direction"] == "left"
        _walk_towards(agent, math.pi / 2 if left else -math.pi / 2)
        t_min, t_max = world.road_band_t(agent.road, agent.s)
        self.stop_t = t_max + self.settings["beyond"] if left else t_min - self.settings["beyond"]
        self.left = left

    def accel(self, agent, world, time_s):
        # Walk at `speed`; brake just hard enough to stop at the far-side spot.
        remaining = (self.stop_t - agent.t) if self.left else (agent.t - self.stop_t)
        a_max = self.settings["accel"]
        v = agent.speed
        if remaining <= 0.0:
            return -v / 0.1  # stop within a few steps
        if v * v >= 2.0 * (2.0 * a_max) * remaining:
            return -v * v / (2.0 * remaining)
        return _speed_tracking(agent, self.settings["speed"], a_max, 2.0 * a_max, world.dt)

    def ended(self, agent, world, time_s):
        # Stopped on the far side.
        past = (agent.t >= self.stop_t) if self.left else (agent.t <= self.stop_t)
        return past and agent.speed <= ENDED_SPEED_TOL_MS


def _walk_towards(agent: AgentState, heading_rel: float) -> None:
    agent.heading_rel = heading_rel if heading_rel != 0.0 else 0.0
    agent.lc_duration_s = 0.0
    agent.t_target = agent.t


def _lane_to_the_left(lane: int) -> int:
    """The adjacent lane on the +t side (agents drive along +s: that is their left),
    skipping the centre lane 0."""
    return lane + 1 if lane != -1 else 1


def _nearest_ahead(agent: AgentState, world) -> str:
    """The name of the actor ahead in the agent's lane (`neighbours.nearest_ahead`), or ""."""
    m, _ = nearest_ahead(world.occupants(agent.road), agent)
    return "" if m is None else m.name


def begin_lane_change(agent: AgentState, world, lane: int, duration_s: float, time_s: float,
                      shape: str = "quintic") -> None:
    """Start a lateral move (a dynamics shape, quintic by default) from the agent's
    current offset to `lane`'s centre; `step` jumps there at the next step."""
    agent.lane = lane
    agent.lc_shape = shape
    agent.lc_keeps_station = False
    if shape == "step":
        duration_s = 0.0
    agent.heading_rel = 0.0
    agent.t_start = agent.t
    agent.t_target = world.lane_t(agent.road, lane, agent.s)
    agent.lane_anchor = (lane, None, agent.t_target) if world.lane_moves(agent.road, lane) else None
    agent.lc_start_s = time_s
    agent.lc_duration_s = duration_s
    agent.lc_centre = None
    if duration_s > 0.0:
        # As esmini: the move is an offset from the target lane's centre, which it follows.
        span_m = max(agent.speed, 1.0) * duration_s * LC_SPAN_FACTOR + LC_SPAN_MARGIN_M
        stations = [agent.s + i * LC_SAMPLE_M for i in range(int(span_m / LC_SAMPLE_M) + 2)]
        centres = [world.lane_t(agent.road, lane, x) for x in stations]
        if all(math.isfinite(c) for c in centres) and max(centres) - min(centres) > 1e-9:
            agent.lc_centre = (stations, centres, agent.t_target)


def advance(agent: AgentState, accel: float, time_s: float, dt: float) -> None:
    """Integrate an agent's road-frame kinematics from `time_s` over `dt` [s]."""
    agent.accel = accel
    # (each of the agent's numbers read once: they are views of the agents' arrays)
    speed = agent.speed = max(0.0, agent.speed + accel * dt)
    # `speed` is the speed along the agent's own path: on a bend its station (measured on
    # the reference line) moves by speed / ground_scale.
    if agent.heading_rel:
        agent.s += speed * math.cos(agent.heading_rel) * dt / agent.ground_scale
        agent.t = agent.t_target = agent.t + speed * math.sin(agent.heading_rel) * dt
    else:
        t_next = lateral_profile(agent, time_s + dt)
        step = speed * dt
        if agent.placed:
            step, agent.placed = 0.0, False
        t = agent.t
        if t_next != t and not agent.lc_keeps_station:  # a lane change: the ground splits into along and across
            across = t_next - t
            step = math.sqrt(max(step * step - across * across, 0.0))
        agent.s += step / agent.ground_scale
        agent.t = t_next
        settle_lane_change(agent, time_s + dt, t_next)


def relative_heading(agent: AgentState, time_s: float, dt: float) -> float:
    """Body heading relative to the road [rad]: walking direction, or the slope of the
    lateral profile during a lane change."""
    if agent.heading_rel:
        return agent.heading_rel
    if agent.lc_duration_s > 0 and time_s < agent.lc_start_s + agent.lc_duration_s:
        lat_rate = (lateral_profile(agent, time_s + dt) - agent.t) / dt
        return math.atan2(lat_rate, max(agent.speed, 0.1))
    return 0.0


def lateral_profile(agent: AgentState, time_s: float) -> float:
    """Lateral offset [m] of an agent on its lane-change profile at `time_s` (onto a lane
    whose centre moves: that centre where the agent is, plus the offset left)."""
    if agent.lc_duration_s <= 0.0:
        return agent.t_target
    u = (time_s - agent.lc_start_s) / agent.lc_duration_s
    if agent.lc_centre is not None:
        stations, centres, start_centre = agent.lc_centre
        i = min(max(bisect.bisect_right(stations, agent.s) - 1, 0), len(stations) - 2)
        f = min(max((agent.s - stations[i]) / (stations[i + 1] - stations[i]), 0.0), 1.0)
        centre = centres[i] + f * (centres[i + 1] - centres[i])
        return centre + (agent.t_start - start_centre) * (1.0 - blend(agent.lc_shape, u))
    return agent.t_start + (agent.t_target - agent.t_start) * blend(agent.lc_shape, u)


def settle_lane_change(agent: AgentState, time_s: float, t: float) -> None:
    """Once a change onto a moving lane centre is over, the agent holds the offset it ended
    at (as after any change)."""
    if agent.lc_centre is not None and time_s + 1e-9 >= agent.lc_start_s + agent.lc_duration_s:
        agent.t_target, agent.t_start, agent.lc_centre = t, t, None
