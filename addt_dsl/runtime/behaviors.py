"""Traffic behaviours, one registered class per DSL keyword.

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

from addt_dsl import units
from addt_dsl.registry import BEHAVIORS, ParamSpec


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


class Behavior:
    keyword = ""
    channel = "longitudinal"  # "longitudinal" | "lateral"
    params: tuple[ParamSpec, ...] = ()
    doc = ""

    def __init__(self, settings: dict):
        self.settings = {p.name: settings.get(p.name, p.default) for p in self.params}

    def start(self, agent: AgentState, world, time_s: float) -> None:
        """Called when the behaviour becomes active."""

    def accel(self, agent: AgentState, world, time_s: float) -> float:
        return 0.0


def _speed_tracking(agent: AgentState, target: float, a_max: float, b_max: float) -> float:
    # First-order tracking with a 1 s time constant, clipped to comfort limits.
    return max(-b_max, min(a_max, target - agent.speed))


@BEHAVIORS.register
class Cruise(Behavior):
    keyword = "cruise"
    params = (
        ParamSpec("speed", units.SPEED, required=True, low=0.0, doc="target speed"),
        ParamSpec("accel", units.ACCELERATION, default=2.0, low=0.0, doc="max acceleration"),
        ParamSpec("decel", units.ACCELERATION, default=3.0, low=0.0, doc="max deceleration"),
    )
    doc = "Hold a target speed."

    def accel(self, agent, world, time_s):
        s = self.settings
        return _speed_tracking(agent, s["speed"], s["accel"], s["decel"])


@BEHAVIORS.register
class Idm(Behavior):
    keyword = "idm"
    aliases = ("follow",)
    params = (
        ParamSpec("speed", units.SPEED, required=True, low=0.0, doc="desired speed"),
        ParamSpec("time_gap", units.TIME, default=1.5, low=0.0, doc="desired time headway"),
        ParamSpec("min_gap", units.LENGTH, default=2.0, low=0.0, doc="jam distance"),
        ParamSpec("accel", units.ACCELERATION, default=1.5, low=0.01, doc="max acceleration"),
        ParamSpec("decel", units.ACCELERATION, default=2.0, low=0.01, doc="comfortable deceleration"),
    )
    doc = "Intelligent Driver Model car-following behind the nearest actor ahead in the lane."

    def accel(self, agent, world, time_s):
        p = self.settings
        v0 = max(p["speed"], 0.1)
        free = 1.0 - (agent.speed / v0) ** 4
        lead = world.leader_of(agent)
        if lead is None:
            return p["accel"] * free
        gap, lead_speed = lead
        dv = agent.speed - lead_speed
        s_star = p["min_gap"] + max(0.0, agent.speed * p["time_gap"]
                                    + agent.speed * dv / (2.0 * math.sqrt(p["accel"] * p["decel"])))
        return p["accel"] * (free - (s_star / max(gap, 0.1)) ** 2)


@BEHAVIORS.register
class Brake(Behavior):
    keyword = "brake"
    aliases = ("sudden_brake",)
    params = (
        ParamSpec("decel", units.ACCELERATION, default=6.0, low=0.0, high=12.0, doc="braking deceleration"),
        ParamSpec("to_speed", units.SPEED, default=0.0, low=0.0, doc="speed at which braking ends"),
    )
    doc = "Brake at a fixed deceleration down to a speed (default: standstill)."

    def accel(self, agent, world, time_s):
        if agent.speed <= self.settings["to_speed"] + 1e-3:
            return 0.0
        return -self.settings["decel"]


@BEHAVIORS.register
class LaneChange(Behavior):
    keyword = "lane_change"
    channel = "lateral"
    params = (
        ParamSpec("to", None, kind="int", required=True, doc="target lane id (OpenDRIVE convention)"),
        ParamSpec("duration", units.TIME, default=4.0, low=0.5, doc="time to complete the change"),
    )
    doc = "Move to another lane with a smooth (quintic) lateral profile."

    def start(self, agent, world, time_s):
        begin_lane_change(agent, world, int(round(self.settings["to"])), self.settings["duration"], time_s)


@BEHAVIORS.register
class CutIn(LaneChange):
    keyword = "cut_in"
    params = (
        ParamSpec("to", None, kind="int", required=True, doc="lane to cut into"),
        ParamSpec("duration", units.TIME, default=2.0, low=0.5, doc="time to complete the cut-in"),
    )
    doc = "An abrupt lane change into another lane (typically in front of the ego)."


@BEHAVIORS.register
class Overtake(Behavior):
    keyword = "overtake"
    params = (
        ParamSpec("speed", units.SPEED, required=True, low=0.0, doc="passing speed"),
        ParamSpec("target", None, kind="name", default="", doc="actor to pass (default: the nearest one ahead in the lane)"),
        ParamSpec("lane", None, kind="int", default=0, doc="passing lane (default: the next lane to the left)"),
        ParamSpec("margin", units.LENGTH, default=8.0, low=0.0, doc="gap ahead of the target before cutting back in"),
        ParamSpec("duration", units.TIME, default=3.0, low=0.5, doc="duration of each lane change"),
        ParamSpec("accel", units.ACCELERATION, default=2.0, low=0.0, doc="max acceleration"),
        ParamSpec("decel", units.ACCELERATION, default=3.0, low=0.0, doc="max deceleration"),
    )
    doc = ("Pull out into the passing lane, pass the target at `speed` and return to the "
           "original lane once `margin` ahead of it; then hold `speed`.")

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
        return _speed_tracking(agent, s["speed"], s["accel"], s["decel"])


@BEHAVIORS.register
class Walk(Behavior):
    keyword = "walk"
    params = (
        ParamSpec("speed", units.SPEED, default=1.4, low=0.0, high=15.0, doc="walking (or riding) speed"),
        ParamSpec("heading", units.ANGLE, default=0.0, low=-math.pi, high=math.pi,
                  doc="direction relative to the road: 0 along +s, 90 deg to the left"),
        ParamSpec("accel", units.ACCELERATION, default=1.0, low=0.01, doc="max acceleration"),
    )
    doc = "Move at a speed and a heading relative to the road (pedestrians, cyclists off the lane)."

    def start(self, agent, world, time_s):
        _walk_towards(agent, self.settings["heading"])

    def accel(self, agent, world, time_s):
        return _speed_tracking(agent, self.settings["speed"], self.settings["accel"], 3.0)


@BEHAVIORS.register
class Cross(Behavior):
    keyword = "cross"
    params = (
        ParamSpec("speed", units.SPEED, default=1.4, low=0.0, high=15.0, doc="crossing speed"),
        ParamSpec("direction", None, kind="word", default="left", choices=("left", "right"),
                  doc="side of the road to walk to, seen along +s"),
        ParamSpec("beyond", units.LENGTH, default=1.0, low=0.0, doc="stop this far past the road edge"),
        ParamSpec("accel", units.ACCELERATION, default=1.0, low=0.01, doc="max acceleration"),
    )
    doc = "Walk straight across the road to the other side and stop there."

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
        return _speed_tracking(agent, self.settings["speed"], a_max, 2.0 * a_max)


def _walk_towards(agent: AgentState, heading_rel: float) -> None:
    agent.heading_rel = heading_rel if heading_rel != 0.0 else 0.0
    agent.lc_duration_s = 0.0
    agent.t_target = agent.t


def _lane_to_the_left(lane: int) -> int:
    """The adjacent lane on the +t side (agents drive along +s: that is their left),
    skipping the centre lane 0."""
    return lane + 1 if lane != -1 else 1


def _nearest_ahead(agent: AgentState, world) -> str:
    best, best_s = "", math.inf
    for name, s, t, _, _ in world.occupants(agent.road):
        if name != agent.name and s > agent.s and abs(t - agent.t) < 1.8 and s < best_s:
            best, best_s = name, s
    return best


def begin_lane_change(agent: AgentState, world, lane: int, duration_s: float, time_s: float) -> None:
    """Start a quintic lateral move from the agent's current offset to `lane`'s centre."""
    agent.lane = lane
    agent.heading_rel = 0.0
    agent.t_start = agent.t
    agent.t_target = world.lane_t(agent.road, lane, agent.s)
    agent.lc_start_s = time_s
    agent.lc_duration_s = duration_s


def advance(agent: AgentState, accel: float, time_s: float, dt: float) -> None:
    """Integrate an agent's road-frame kinematics from `time_s` over `dt` [s]."""
    agent.accel = accel
    agent.speed = max(0.0, agent.speed + accel * dt)
    if agent.heading_rel:
        agent.s += agent.speed * math.cos(agent.heading_rel) * dt
        agent.t += agent.speed * math.sin(agent.heading_rel) * dt
        agent.t_target = agent.t
    else:
        agent.s += agent.speed * dt
        agent.t = lateral_profile(agent, time_s + dt)


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
    """Lateral offset [m] of an agent on its quintic lane-change profile at `time_s`."""
    if agent.lc_duration_s <= 0.0:
        return agent.t_target
    u = min(1.0, max(0.0, (time_s - agent.lc_start_s) / agent.lc_duration_s))
    blend = u * u * u * (10.0 - 15.0 * u + 6.0 * u * u)
    return agent.t_start + (agent.t_target - agent.t_start) * blend
