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

import math
from dataclasses import dataclass

from addt_dsl.registry import BEHAVIORS
from addt_dsl.runtime.neighbours import nearest_ahead
from addt_dsl.specs import behaviors as S


@dataclass
class AgentState:
    """Road-frame state of a traffic agent (m, m/s)."""

    name: str
    road: str
    s: float
    t: float
    speed: float
    accel: float
    length_m: float
    width_m: float
    lane: int
    t_target: float
    t_start: float = 0.0
    lc_start_s: float = 0.0  # time the current lateral manoeuvre began [s]
    lc_duration_s: float = 0.0
    # Direction of motion relative to the road's +s direction [rad]; non-zero for
    # walkers: they move at this angle instead of following a lane.
    heading_rel: float = 0.0
    lc_shape: str = "quintic"  # blend of the current lateral manoeuvre (see SHAPES)
    # The current lateral manoeuvre leaves the station's progress whole (a lane offset, as
    # esmini moves one); a lane change takes its sideways part from the step along the road.
    lc_keeps_station: bool = False
    moved: bool = False  # it has had a speed above 0: its declared yaw no longer holds
    # Ground covered per metre of station at its offset [m/m] (`FastRoad.ground_scale`),
    # set where it is posed: its station advances by speed / ground_scale.
    ground_scale: float = 1.0


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


def _speed_tracking(agent: AgentState, target: float, a_max: float, b_max: float, dt: float) -> float:
    """Accelerate at `a_max` (brake at `b_max`) until the target speed, landing on it
    within one step: an acceleration setting is the acceleration the agent has. (A
    first-order lag here once gave 1.32 m/s after 3 s at `accel 2 m/s^2`.)"""
    return max(-b_max, min(a_max, (target - agent.speed) / dt))


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




@BEHAVIORS.implements
class Cruise(S.Cruise, Behavior):
    transition: SpeedTransition | None = None  # a shaped or timed change, set by start()

    def start(self, agent, world, time_s):
        s = self.settings
        self.transition = None
        if s["shape"] != "linear" or s["duration"] is not None:
            # A live target is taken as it is at the start; it is followed once reached.
            self.transition = SpeedTransition(agent.speed, max(0.0, self.value("speed", world)), time_s,
                                              s["shape"], s["accel"], s["decel"], s["duration"])

    def accel(self, agent, world, time_s):
        s = self.settings
        tr = self.transition
        if tr is not None and tr.active(time_s, world.dt):
            return tr.accel(agent, time_s, world.dt)
        # Linear at the rate limits: the same as tracking the target.
        return _speed_tracking(agent, max(0.0, self.value("speed", world)), s["accel"], s["decel"], world.dt)

    def ended(self, agent, world, time_s):
        # At the target speed: the shaped change is over, or the speed is on the target.
        if self.transition is not None:
            return not self.transition.active(time_s, world.dt)
        return abs(agent.speed - max(0.0, self.value("speed", world))) < ENDED_SPEED_TOL_MS


@BEHAVIORS.implements
class SpeedProfile(S.SpeedProfile, Behavior):

    def start(self, agent, world, time_s):
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
        free = idm_free(p, agent.speed)
        lead = world.leader_of(agent)
        if lead is None:
            return p.accel * free
        return idm_accel(p, agent.speed, free, *lead)

    _params = None


class IdmParams:
    """IDM settings with their per-agent constants: floats (one agent) or arrays over agents."""

    def __init__(self, v0, accel, time_gap, min_gap, two_sqrt_ab):
        self.v0, self.accel, self.time_gap, self.min_gap, self.two_sqrt_ab = v0, accel, time_gap, min_gap, two_sqrt_ab

    @classmethod
    def of(cls, p: dict) -> IdmParams:
        return cls(max(p["speed"], 0.1), p["accel"], p["time_gap"], p["min_gap"], 2.0 * math.sqrt(p["accel"] * p["decel"]))


class _Floats:
    """The operations of the IDM formulas on floats (`fleet.ARRAYS`: on numpy arrays, the same values)."""

    power = staticmethod(pow)  # libm's pow, as Python's `**`

    @staticmethod
    def positive(x):
        return max(0.0, x)

    @staticmethod
    def at_least(x, low):
        return max(x, low)


def idm_free(p: IdmParams, v, ops=_Floats):
    """The free-road term `1 - (v / v0) ** 4` of IDM."""
    return 1.0 - ops.power(v / p.v0, 4)


def idm_accel(p: IdmParams, v, free, gap, lead_speed, ops=_Floats):
    """IDM's acceleration [m/s^2] behind a leader `gap` [m] ahead at `lead_speed` [m/s]
    (`free`: `idm_free`): the one definition, for floats or, with `ops`, arrays over agents."""
    dv = v - lead_speed
    s_star = p.min_gap + ops.positive(v * p.time_gap + v * dv / p.two_sqrt_ab)
    return p.accel * (free - ops.power(s_star / ops.at_least(gap, 0.1), 2))


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


@BEHAVIORS.implements
class Synchronize(S.Synchronize, Behavior):

    def start(self, agent, world, time_s):
        if self.settings["heading"] is not None:
            _walk_towards(agent, self.settings["heading"])
        self.final = None

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
        master = world.actor_station(s["master"])
        to_go = s["master_at"] - master[0] if master is not None else 0.0
        if self.final is None and to_go <= 0.0:  # the master has arrived: synchronisation ends
            self.final = s["final_speed"] if s["final_speed"] is not None else agent.speed
        if self.final is not None:
            return _speed_tracking(agent, self.final, s["accel"], s["decel"], world.dt)
        arrival_s = to_go / master[1] if master[1] > 1e-3 else math.inf
        wanted = max(0.0, self.remaining_m(agent)) / arrival_s
        return _speed_tracking(agent, min(wanted, s["max_speed"]), s["accel"], s["decel"], world.dt)

    def ended(self, agent, world, time_s):
        return self.final is not None  # the master has arrived


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
        # Brake at `decel`, landing on `to_speed` instead of overshooting below it.
        return min(0.0, max(-self.settings["decel"], (self.settings["to_speed"] - agent.speed) / world.dt))

    def ended(self, agent, world, time_s):
        return agent.speed <= self.settings["to_speed"] + ENDED_SPEED_TOL_MS


@BEHAVIORS.implements
class LaneChange(S.LaneChange, Behavior):

    def start(self, agent, world, time_s):
        other = self.settings["to_lane_of"]
        lane = world.actor_lane(other) if other else int(round(self.settings["to"]))
        if lane is None:  # the other actor is off the lanes: keep to the current one
            lane = agent.lane
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

    def accel(self, agent, world, time_s):
        return _speed_tracking(agent, self.settings["speed"], self.settings["accel"], 3.0, world.dt)


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
    agent.lc_start_s = time_s
    agent.lc_duration_s = duration_s


def advance(agent: AgentState, accel: float, time_s: float, dt: float) -> None:
    """Integrate an agent's road-frame kinematics from `time_s` over `dt` [s]."""
    agent.accel = accel
    agent.speed = max(0.0, agent.speed + accel * dt)
    # `speed` is the speed along the agent's own path: on a bend its station (measured on
    # the reference line) moves by speed / ground_scale.
    if agent.heading_rel:
        agent.s += agent.speed * math.cos(agent.heading_rel) * dt / agent.ground_scale
        agent.t += agent.speed * math.sin(agent.heading_rel) * dt
        agent.t_target = agent.t
    else:
        t_next = lateral_profile(agent, time_s + dt)
        step = agent.speed * dt
        if t_next != agent.t and not agent.lc_keeps_station:  # a lane change: the ground splits into along and across
            across = t_next - agent.t
            step = math.sqrt(max(step * step - across * across, 0.0))
        agent.s += step / agent.ground_scale
        agent.t = t_next


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
    """Lateral offset [m] of an agent on its lane-change profile at `time_s`."""
    if agent.lc_duration_s <= 0.0:
        return agent.t_target
    u = (time_s - agent.lc_start_s) / agent.lc_duration_s
    return agent.t_start + (agent.t_target - agent.t_start) * blend(agent.lc_shape, u)
