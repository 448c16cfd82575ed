"""Traffic behaviours' specs: keyword, channel, settings, docs and the checks across settings
(`validate`); the implementations are in `addt_dsl/runtime/behaviors.py`."""

from __future__ import annotations

import math

from addt_dsl import units
from addt_dsl.registry import BEHAVIORS, ParamSpec


# Dynamics shapes (OpenSCENARIO TransitionDynamics; the blends are in the runtime's `SHAPES`):
# lane changes take any, speed changes all but `quintic`.
SHAPES = ("step", "linear", "cubic", "sinusoidal", "quintic")
SPEED_SHAPES = ("step", "linear", "cubic", "sinusoidal")
# A shape's peak second derivative relative to (change / duration^2), as esmini's
# TransitionDynamics (GetTargetParamValByPrimPrimPeak) gives it: the duration that keeps a
# lateral move's peak acceleration at a limit is sqrt(factor * |change| / limit). esmini uses
# the cubic's 6 for `linear` too (a linear blend's acceleration is infinite at its ends);
# the quintic's peak is 10 / sqrt(3).
PEAK_CURVATURE = {"linear": 6.0, "cubic": 6.0, "sinusoidal": math.pi ** 2 / 2, "quintic": 10.0 / math.sqrt(3.0)}
SHAPE_SETTING = ParamSpec("shape", None, kind="word", default="linear", choices=SPEED_SHAPES,
                          doc="dynamics shape of the speed change")
DURATION_SETTING = ParamSpec("duration", units.TIME, default=None, low=0.0,
                             doc="time the speed change takes (default: from the rate limits and shape)")


class BehaviorSpec:
    keyword = ""
    channel = "longitudinal"  # "longitudinal" | "lateral"
    params: tuple[ParamSpec, ...] = ()
    doc = ""


@BEHAVIORS.register
class Cruise(BehaviorSpec):
    keyword = "cruise"
    params = (
        ParamSpec("speed", units.SPEED, required=True, low=0.0, live=True,
                  doc="target speed; may follow other actors (`1.2 * speed(ego)`)"),
        ParamSpec("accel", units.ACCELERATION, default=2.0, low=0.0, doc="max acceleration"),
        ParamSpec("decel", units.ACCELERATION, default=3.0, low=0.0, doc="max deceleration"),
        SHAPE_SETTING,
        DURATION_SETTING,
        ParamSpec("distance", units.LENGTH, default=None, low=0.0,
                  doc="distance the speed change covers: it takes 2 distance / (v0 + v1), v0 the speed "
                      "at its start (OpenSCENARIO's dynamicsDimension distance)"),
        # A vehicle's Performance in OpenSCENARIO: esmini stretches a change whose peak rate
        # exceeds it (TransitionDynamics::SetMaxRate), at a rate, over a time or a distance.
        ParamSpec("max_accel", units.ACCELERATION, default=None, low=0.0,
                  doc="a change whose peak acceleration would exceed this takes longer, its peak at "
                      "this (unset: unbounded)"),
        ParamSpec("max_decel", units.ACCELERATION, default=None, low=0.0,
                  doc="the same bound on slowing down"),
    )
    doc = ("Change to a target speed (at the rate limits, over `duration` or over `distance`, "
           "with a dynamics shape) and hold it.")

    @staticmethod
    def validate(values: dict) -> list[tuple[str, str]]:
        """Problems of constant settings, as (setting, message)."""
        if "duration" in values and "distance" in values:
            return [("distance", "a speed change takes a `duration` or a `distance`, not both")]
        return []

@BEHAVIORS.register
class SpeedProfile(BehaviorSpec):
    keyword = "speed_profile"
    params = (
        ParamSpec("times", units.TIME, kind="list", required=True, low=0.0,
                  doc="times of the points, from the start of the behaviour, increasing"),
        ParamSpec("speeds", units.SPEED, kind="list", required=True, low=0.0, doc="speed at each time"),
        ParamSpec("shape", None, kind="word", default="linear", choices=SPEED_SHAPES,
                  doc="dynamics shape between consecutive points (mode `position`)"),
        ParamSpec("mode", None, kind="word", default="position", choices=("position", "follow"),
                  doc="`position`: meet every point; `follow`: follow the slopes between the points "
                      "within the limits below, with limited jerk at the corners (esmini's plan)"),
        # The limits of mode `follow` (OpenSCENARIO DynamicConstraints); unset: unlimited.
        ParamSpec("accel", units.ACCELERATION, default=None, low=0.0, doc="max acceleration (mode `follow`)"),
        ParamSpec("decel", units.ACCELERATION, default=None, low=0.0, doc="max deceleration (mode `follow`)"),
        ParamSpec("accel_rate", units.JERK, default=None, low=0.0,
                  doc="max rate of change of acceleration, speeding up (mode `follow`)"),
        ParamSpec("decel_rate", units.JERK, default=None, low=0.0,
                  doc="max rate of change of acceleration, slowing down (mode `follow`)"),
        ParamSpec("max_speed", units.SPEED, default=None, low=0.0, doc="max speed (mode `follow`)"),
    )
    FOLLOW_LIMITS = ("accel", "decel", "accel_rate", "decel_rate", "max_speed")
    doc = ("Follow time/speed points (OpenSCENARIO SpeedProfileAction): mode `position` meets "
           "every point; mode `follow` plans esmini's jerk-limited profile along the slopes "
           "between them; then hold the last speed.")
    @staticmethod
    def validate(values: dict) -> list[tuple[str, str]]:
        """Problems of constant settings, as (setting, message)."""
        times, speeds = values.get("times"), values.get("speeds")  # None: not constants
        out = []
        follow = values.get("mode") == "follow"
        for name in SpeedProfile.FOLLOW_LIMITS if not follow else ():
            if name in values:
                out.append((name, f"`{name}` limits a speed profile in `mode follow` only: add `mode follow`"))
        if follow and values.get("shape", "linear") != "linear":
            out.append(("shape", "a speed profile in `mode follow` has no shape: it plans its own corners"))
        if isinstance(times, list) and isinstance(speeds, list) and len(times) != len(speeds):
            out.append(("speeds", f"{len(speeds)} speeds for {len(times)} times: give one speed per time"))
        if isinstance(times, list) and any(b <= a for a, b in zip(times, times[1:])):
            out.append(("times", "the times of a speed profile must increase"))
        return out

@BEHAVIORS.register
class Idm(BehaviorSpec):
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

@BEHAVIORS.register
class KeepGap(BehaviorSpec):
    keyword = "keep_gap"
    params = (
        ParamSpec("target", None, kind="name", required=True, doc="actor to keep the gap to"),
        ParamSpec("distance", units.LENGTH, low=0.0, doc="bumper-to-bumper gap to keep"),
        ParamSpec("time_gap", units.TIME, low=0.0, doc="instead of `distance`: gap as time at the target's speed"),
        ParamSpec("side", None, kind="word", default="behind", choices=("behind", "ahead"),
                  doc="keep the gap behind the target or ahead of it"),
        ParamSpec("accel", units.ACCELERATION, default=3.0, low=0.01, doc="max acceleration"),
        ParamSpec("decel", units.ACCELERATION, default=6.0, low=0.01, doc="max deceleration"),
    )
    doc = ("Keep a distance or time gap to another actor, continuously (OpenSCENARIO "
           "LongitudinalDistanceAction, freespace, continuous): a critically damped spring on the "
           "gap error whose stiffness is 0.4/s^2 times the limit it pushes against, as esmini executes it.")
    @staticmethod
    def validate(values: dict) -> list[tuple]:
        if ("distance" in values) == ("time_gap" in values):
            return [("distance", "give the gap once: `distance D` or `time_gap T`", "E0105")]
        return []

@BEHAVIORS.register
class Synchronize(BehaviorSpec):
    keyword = "synchronize"
    params = (
        ParamSpec("master", None, kind="name", required=True, doc="actor whose arrival sets the time"),
        ParamSpec("master_at", units.LENGTH, required=True, low=0.0,
                  doc="station along its road the master arrives at (its centre)"),
        ParamSpec("target_s", units.LENGTH, low=0.0, doc="station of the own target point"),
        ParamSpec("target_t", units.LENGTH, doc="lateral offset of the own target point (left positive)"),
        ParamSpec("heading", units.ANGLE, low=-math.pi, high=math.pi,
                  doc="direction to move relative to the road, as `walk` (default: as it moves now)"),
        ParamSpec("max_speed", units.SPEED, default=15.0, low=0.1, doc="speed limit while synchronising"),
        ParamSpec("accel", units.ACCELERATION, default=5.0, low=0.01, doc="max acceleration"),
        ParamSpec("decel", units.ACCELERATION, default=5.0, low=0.01, doc="max deceleration"),
        ParamSpec("final_speed", units.SPEED, low=0.0, live=True,
                  doc="speed to have on arrival, planned as esmini does (may follow the master: "
                      "`speed(ego) - 3 m/s`; default: keep the speed)"),
        ParamSpec("tolerance", units.LENGTH, default=0.0, low=0.0,
                  doc="arrived within this distance of the own target point"),
        ParamSpec("master_tolerance", units.LENGTH, default=0.0, low=0.0,
                  doc="the master arrived within this distance of its point"),
    )
    doc = ("Adjust the speed to reach a point when another actor reaches its point (OpenSCENARIO "
           "SynchronizeAction): without `final_speed`, at every step the remaining distance over the "
           "master's time to arrival at its current speed (within `max_speed`, `accel`, `decel`); "
           "with it, esmini's speed profile that arrives at that speed: one constant acceleration, "
           "or two phases (speed up then slow down, or the reverse), or a stop and a wait, without "
           "the limits. Ends when either is within its tolerance of its point or has passed it.")
    @staticmethod
    def validate(values: dict) -> list[tuple]:
        if "target_s" not in values and "target_t" not in values:
            return [("master", "give the own target point: `target_s S` and/or `target_t T`", "E0105")]
        return []

@BEHAVIORS.register
class Trajectory(BehaviorSpec):
    keyword = "trajectory"
    params = (
        ParamSpec("s", units.LENGTH, kind="list",
                  doc="stations of the waypoints along the road's reference line (OpenDRIVE s)"),
        ParamSpec("t", units.LENGTH, kind="list",
                  doc="lateral offsets of the waypoints from the reference line, left of +s positive (OpenDRIVE t)"),
        ParamSpec("x", units.LENGTH, kind="list", doc="instead of `s`/`t`: world x of the waypoints"),
        ParamSpec("y", units.LENGTH, kind="list", doc="instead of `s`/`t`: world y of the waypoints"),
        ParamSpec("times", units.TIME, kind="list", low=0.0,
                  doc="time to be at each waypoint, from the start of the behaviour, met exactly: the speed "
                      "changes at the waypoints at once, a waypoint repeated with a later time is a wait, and "
                      "after the last one it keeps its last segment's speed (default: at `speed`)"),
        ParamSpec("speed", units.SPEED, default=None, low=0.0,
                  doc="speed without `times` (default: the actor's speed when the behaviour starts)"),
        ParamSpec("max_speed", units.SPEED, default=40.0, low=0.1, doc="speed limit with `times`"),
        ParamSpec("accel", units.ACCELERATION, default=5.0, low=0.01, doc="max acceleration (without `times`)"),
        ParamSpec("decel", units.ACCELERATION, default=8.0, low=0.01, doc="max deceleration (without `times`)"),
    )
    doc = ("Follow waypoints in road (`s`, `t`) or world (`x`, `y`) coordinates, at a speed or "
           "meeting given times (OpenSCENARIO FollowTrajectoryAction, polyline); then drive on "
           "along the road at the reached offset.")
    @staticmethod
    def validate(values: dict) -> list[tuple]:
        road = [k for k in ("s", "t") if k in values]
        world = [k for k in ("x", "y") if k in values]
        if not (len(road) == 2 and not world) and not (len(world) == 2 and not road):
            # Name a setting to drop where there is one too many, else the first missing.
            key = world[0] if len(road) == 2 else road[0] if len(world) == 2 else (road + world + ["s"])[0]
            return [(key, "give the waypoints once: `s [...] t [...]` (road) or `x [...] y [...]` (world)",
                     "E0105")]
        lists = [values[k] for k in ("s", "t", "x", "y", "times") if isinstance(values.get(k), list)]
        if len({len(v) for v in lists}) > 1:
            return [("times" if "times" in values else "t",
                     "the waypoint lists differ in length: one value per waypoint in each", "E0204")]
        times = values.get("times")
        if isinstance(times, list) and any(b <= a for a, b in zip(times, times[1:])):
            return [("times", "the times of a trajectory must increase")]
        return []

@BEHAVIORS.register
class Brake(BehaviorSpec):
    keyword = "brake"
    aliases = ("sudden_brake",)
    params = (
        ParamSpec("decel", units.ACCELERATION, default=6.0, low=0.0, high=12.0, doc="braking deceleration"),
        ParamSpec("to_speed", units.SPEED, default=0.0, low=0.0, doc="speed at which braking ends"),
    )
    doc = "Brake at a fixed deceleration down to a speed (default: standstill)."

def lanes_over(lane: int, count: int) -> int:
    """The lane `count` lanes to the left (negative: right) of `lane` for a driver in it
    under right-hand traffic (lanes right of the reference line drive along +s), lane 0
    skipped (as esmini's relative target lane)."""
    target = lane + count * (1 if lane < 0 else -1)
    if target == 0 or (target > 0) != (lane > 0):
        target = (1 if target > lane else -1) * (abs(target) + 1)
    return target


@BEHAVIORS.register
class LaneChange(BehaviorSpec):
    keyword = "lane_change"
    channel = "lateral"
    params = (
        ParamSpec("to", None, kind="int", doc="target lane id (OpenDRIVE convention)"),
        ParamSpec("to_lane_of", None, kind="name", default="",
                  doc="instead of `to`: the lane another actor is in when the change starts"),
        ParamSpec("lanes", None, kind="int", default=0, low=-20, high=20,
                  doc="with `to_lane_of`: that many lanes to the actor's left (negative: right), "
                      "as its driver sees it under right-hand traffic, lane 0 skipped"),
        ParamSpec("duration", units.TIME, default=4.0, low=0.5, doc="time to complete the change"),
        ParamSpec("shape", None, kind="word", default="quintic", choices=SHAPES,
                  doc="lateral dynamics shape (quintic: zero lateral speed and acceleration at both ends)"),
    )
    doc = "Move to another lane with a smooth (quintic, or another dynamics shape) lateral profile."
    @staticmethod
    def validate(values: dict) -> list[tuple]:
        if ("to" in values) == bool(values.get("to_lane_of")):
            return [("to", "give the target lane once: `to LANE` or `to_lane_of ACTOR`", "E0105")]
        if values.get("lanes") and not values.get("to_lane_of"):
            return [("lanes", "`lanes N` counts from another actor's lane: give `to_lane_of ACTOR`", "E0105")]
        return []

@BEHAVIORS.register
class LaneOffset(BehaviorSpec):
    keyword = "lane_offset"
    channel = "lateral"
    params = (
        ParamSpec("to", units.LENGTH, required=True,
                  doc="target offset from the centre of the actor's lane, left of +s positive"),
        ParamSpec("duration", units.TIME, default=None, low=0.0, doc="time the move takes"),
        ParamSpec("max_lat_accel", units.ACCELERATION, default=None, low=0.01,
                  doc="instead of `duration`: the shape's peak lateral acceleration, which sets the time"),
        ParamSpec("shape", None, kind="word", default="quintic", choices=SHAPES, doc="lateral dynamics shape"),
    )
    doc = ("Move sideways to an offset from the centre of the lane the actor is in and hold it "
           "(OpenSCENARIO LaneOffsetAction).")
    @staticmethod
    def validate(values: dict) -> list[tuple]:
        if ("duration" in values) == ("max_lat_accel" in values):
            return [("max_lat_accel" if "duration" in values else "to",
                     "give the time of the move once: `duration D` or `max_lat_accel A`", "E0105")]
        return []

@BEHAVIORS.register
class Teleport(BehaviorSpec):
    keyword = "teleport"
    channel = "lateral"
    params = (
        ParamSpec("s", units.LENGTH, required=True, doc="station on the road it is on (OpenDRIVE road coordinates)"),
        ParamSpec("t", units.LENGTH, required=True, doc="lateral offset from the road's reference line, left of +s"),
    )
    doc = ("Move at once to a point of the road the actor is on, keeping its speed and direction "
           "(OpenSCENARIO TeleportAction during the run).")

@BEHAVIORS.register
class CutIn(LaneChange):
    keyword = "cut_in"
    params = (
        ParamSpec("to", None, kind="int", doc="lane to cut into"),
        ParamSpec("to_lane_of", None, kind="name", default="",
                  doc="instead of `to`: the lane another actor is in when the cut-in starts"),
        ParamSpec("duration", units.TIME, default=2.0, low=0.5, doc="time to complete the cut-in"),
        ParamSpec("shape", None, kind="word", default="quintic", choices=SHAPES,
                  doc="lateral dynamics shape"),
    )
    doc = "An abrupt lane change into another lane (typically in front of the ego)."

@BEHAVIORS.register
class Overtake(BehaviorSpec):
    keyword = "overtake"
    params = (
        ParamSpec("speed", units.SPEED, required=True, low=0.0, doc="passing speed"),
        ParamSpec("target", None, kind="name", default="",
                  doc="actor to pass (default: the nearest one ahead in the lane)"),
        ParamSpec("lane", None, kind="int", default=0, doc="passing lane (default: the next lane to the left)"),
        ParamSpec("margin", units.LENGTH, default=8.0, low=0.0, doc="gap ahead of the target before cutting back in"),
        ParamSpec("duration", units.TIME, default=3.0, low=0.5, doc="duration of each lane change"),
        ParamSpec("accel", units.ACCELERATION, default=2.0, low=0.0, doc="max acceleration"),
        ParamSpec("decel", units.ACCELERATION, default=3.0, low=0.0, doc="max deceleration"),
    )
    doc = ("Pull out into the passing lane, pass the target at `speed` and return to the "
           "original lane once `margin` ahead of it; then hold `speed`.")

@BEHAVIORS.register
class Walk(BehaviorSpec):
    keyword = "walk"
    params = (
        ParamSpec("speed", units.SPEED, default=1.4, low=0.0, high=15.0, doc="walking (or riding) speed"),
        ParamSpec("heading", units.ANGLE, default=0.0, low=-math.pi, high=math.pi,
                  doc="direction relative to the road: 0 along +s, 90 deg to the left"),
        ParamSpec("accel", units.ACCELERATION, default=1.0, low=0.01, doc="max acceleration"),
        ParamSpec("decel", units.ACCELERATION, default=3.0, low=0.01, doc="max deceleration"),
        # OpenSCENARIO as CARLA ScenarioRunner runs it: a speed action on a walker completes
        # after a distance or a time, while the walker walks on.
        ParamSpec("distance", units.LENGTH, default=None, low=0.0,
                  doc="it ends once this far in a straight line from where it started (unset: never); "
                      "it walks on"),
        ParamSpec("duration", units.TIME, default=None, low=0.0,
                  doc="it ends this long after it started (unset: never); it walks on"),
    )
    doc = "Move at a speed and a heading relative to the road (pedestrians, cyclists off the lane)."

@BEHAVIORS.register
class Cross(BehaviorSpec):
    keyword = "cross"
    params = (
        ParamSpec("speed", units.SPEED, default=1.4, low=0.0, high=15.0, doc="crossing speed"),
        ParamSpec("direction", None, kind="word", default="left", choices=("left", "right"),
                  doc="side of the road to walk to, seen along +s"),
        ParamSpec("beyond", units.LENGTH, default=1.0, low=0.0, doc="stop this far past the road edge"),
        ParamSpec("accel", units.ACCELERATION, default=1.0, low=0.01, doc="max acceleration"),
    )
    doc = "Walk straight across the road to the other side and stop there."
