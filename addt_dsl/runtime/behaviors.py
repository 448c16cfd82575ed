"""Traffic behaviours, one registered class per DSL keyword.

A behaviour drives one longitudinal or lateral channel of a traffic agent: it returns
an acceleration command [m/s^2] and/or a lateral target (offset from the road
reference line [m]) with a smooth profile. Agents move along their road in (s, t), so
behaviours are pure numpy and need no physics engine.
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
        lane = int(round(self.settings["to"]))
        agent.lane = lane
        agent.t_start = agent.t
        agent.t_target = world.lane_t(agent.road, lane, agent.s)
        agent.lc_start_s = time_s
        agent.lc_duration_s = self.settings["duration"]


@BEHAVIORS.register
class CutIn(LaneChange):
    keyword = "cut_in"
    params = (
        ParamSpec("to", None, kind="int", required=True, doc="lane to cut into"),
        ParamSpec("duration", units.TIME, default=2.0, low=0.5, doc="time to complete the cut-in"),
    )
    doc = "An abrupt lane change into another lane (typically in front of the ego)."


def lateral_profile(agent: AgentState, time_s: float) -> float:
    """Lateral offset [m] of an agent on its quintic lane-change profile at `time_s`."""
    if agent.lc_duration_s <= 0.0:
        return agent.t_target
    u = min(1.0, max(0.0, (time_s - agent.lc_start_s) / agent.lc_duration_s))
    blend = u * u * u * (10.0 - 15.0 * u + 6.0 * u * u)
    return agent.t_start + (agent.t_target - agent.t_start) * blend
