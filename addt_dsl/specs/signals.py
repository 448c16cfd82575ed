"""Signal functions' specs (oracles and triggers): keyword, argument kinds, dimension and
docs, so the compiler can check formulas; `compute` (a signal from a `Trace`) is in
`addt_dsl/runtime/signals.py`.

`ego.speed` and `speed(ego)` are the same signal; its canonical name is `speed(ego)`.
"""

from __future__ import annotations

from addt_dsl import units
from addt_dsl.registry import SIGNALS

TTC_CAP_S = 99.0  # a TTC above this means "not closing"; keeps robustness finite


class SignalSpec:
    keyword: str = ""
    args: tuple[str, ...] = ("actor",)  # "actor" | "node" | "step" (a named step, `lead.brake_hard`)
    dim = units.DIMENSIONLESS
    boolean = False  # a state (+1 holds, -1 not), usable as a formula on its own
    # Its value at an instant needs the samples before it: oracles only (a `when` condition
    # is checked on the current state alone, where it would read 0).
    history = False
    doc = ""


# Signals that read one field of the actor's track: (keyword, dimension, doc).
FIELDS = (
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
)
FIELD_SPECS: dict[str, type[SignalSpec]] = {}
for _name, _dim, _doc in FIELDS:
    FIELD_SPECS[_name] = SIGNALS.register(type(f"Signal_{_name}", (SignalSpec,),
                                               {"keyword": _name, "dim": _dim, "doc": _doc}))


@SIGNALS.register
class Jerk(SignalSpec):
    keyword = "jerk"
    dim = units.JERK
    history = True
    doc = "time derivative of longitudinal acceleration [m/s^3]"

@SIGNALS.register
class Travelled(SignalSpec):
    keyword = "travelled"
    dim = units.LENGTH
    history = True
    doc = ("distance the actor's centre has covered since the start, summed over the steps [m] "
           "(CARLA's DrivenDistanceTest)")

@SIGNALS.register
class RoadEdge(SignalSpec):
    keyword = "road_edge"
    dim = units.LENGTH
    doc = ("distance from the actor's centre to the outer edge of its road on its side (the lanes of any "
           "type but `none`), negative beyond it: off the road (OpenSCENARIO OffroadCondition, as esmini "
           "measures it) [m]")

@SIGNALS.register
class RoadEnd(SignalSpec):
    keyword = "road_end"
    dim = units.LENGTH
    doc = ("distance left from the actor's centre to the end of its road or route in its driving direction, 0 "
           "at the end (where `at_road_end stop` holds it: OpenSCENARIO EndOfRoadCondition) [m]")

@SIGNALS.register
class Distance(SignalSpec):
    keyword = "distance"
    args = ("actor", "actor")
    dim = units.LENGTH
    doc = "centre-to-centre distance between two actors [m]"

@SIGNALS.register
class Gap(SignalSpec):
    keyword = "gap"
    args = ("actor", "actor")
    dim = units.LENGTH
    doc = ("bumper-to-bumper gap along the road (or the shared route) from the first actor to the "
           "second; between actors on different roads or routes, the centre distance less half "
           "of both lengths [m]")

@SIGNALS.register
class RelSpeed(SignalSpec):
    keyword = "rel_speed"
    args = ("actor", "actor")
    dim = units.SPEED
    doc = ("speed of the first actor minus that of the second, positive when the first is faster "
           "(OpenSCENARIO RelativeSpeedCondition) [m/s]")

@SIGNALS.register
class LatGap(SignalSpec):
    keyword = "lat_gap"
    args = ("actor", "actor")
    dim = units.LENGTH
    doc = ("side-to-side gap across the road between two actors' boxes, negative when they overlap "
           "laterally (OpenSCENARIO RelativeDistanceCondition, lateral, freespace) [m]")

@SIGNALS.register
class LonGap(SignalSpec):
    keyword = "lon_gap"
    args = ("actor", "actor")
    dim = units.LENGTH
    doc = ("free-space gap along the first actor's heading from its box to the second's, both boxes "
           "projected on that heading: positive ahead, negative behind, 0 where the projections "
           "overlap (OpenSCENARIO entity coordinates, longitudinal, freespace, as esmini measures "
           "them) [m]")

@SIGNALS.register
class Ttc(SignalSpec):
    keyword = "ttc"
    args = ("actor", "actor")
    dim = units.TIME
    doc = (f"time to collision of the first actor into the second: along the road (or shared route), "
           f"the bumper gap over the closing speed when they overlap laterally and close in; between "
           f"actors on different roads or routes (or driving different ways), the time until their boxes "
           f"first overlap if both keep their velocity and heading; capped at {TTC_CAP_S:g} s, also "
           f"when they never meet [s]")

@SIGNALS.register
class Latency(SignalSpec):
    keyword = "latency"
    args = ("node",)
    dim = units.TIME
    doc = "latency of a stack node, or `e2e` from sensor timestamp to actuation [s]"

@SIGNALS.register
class ObjectCount(SignalSpec):
    keyword = "objects"
    args = ()
    dim = units.DIMENSIONLESS
    doc = "number of objects the perception reports"

@SIGNALS.register
class Started(SignalSpec):
    keyword = "started"
    args = ("step",)
    boolean = True
    doc = ("whether a named step has fired (started its behaviour or group), also once it ended "
           "(OpenSCENARIO StoryboardElementStateCondition, startTransition)")

@SIGNALS.register
class Ended(SignalSpec):
    keyword = "ended"
    args = ("step",)
    boolean = True
    doc = ("whether a named step's behaviour has completed: a lane change in its lane, a brake at "
           "its speed, a speed profile past its last point, a group when all its steps ended "
           "(OpenSCENARIO StoryboardElementStateCondition, endTransition)")

@SIGNALS.register
class LaneId(SignalSpec):
    keyword = "lane_id"
    args = ("actor",)
    dim = units.DIMENSIONLESS
    doc = ("the OpenDRIVE id of the driving lane the actor is in (the nearest lane centre on "
           "its road or route; NaN off the lanes), recorded only in runs whose formulas read it")

@SIGNALS.register
class WrongWay(SignalSpec):
    keyword = "wrong_way"
    boolean = True
    doc = ("whether the actor's centre is in a driving lane (the nearest lane centre on its road or route) "
           "whose traffic runs against the direction the actor's road or route is driven there, outside "
           "junctions (CARLA's WrongLaneTest); recorded only for the actors a formula reads it of")


@SIGNALS.register
class OffLanes(SignalSpec):
    keyword = "off_lanes"
    boolean = True
    doc = ("whether the actor is off the lanes where vehicles may be, as CARLA's OnSidewalkTest tells it: its "
           "centre in a sidewalk lane of its road or route, or in a lane neither driving nor parking with no "
           "corner of its box in a driving lane and a corner in a sidewalk, or its centre off every lane "
           "(lanes of type `none` are none); recorded only for the actors a formula reads it of")


@SIGNALS.register
class Light(SignalSpec):
    keyword = "light"
    args = ("light",)
    dim = units.DIMENSIONLESS
    doc = "state of a traffic-light controller: compare with `green`, `yellow`, `red` (0, 1, 2)"

@SIGNALS.register
class Var(SignalSpec):
    keyword = "var"
    args = ("variable",)
    dim = units.DIMENSIONLESS
    doc = ("value of a scenario variable (`variables { }`), as the steps that set it left it "
           "(OpenSCENARIO ParameterCondition on a parameter a ParameterSetAction sets)")

@SIGNALS.register
class RedLight(SignalSpec):
    keyword = "red_light"
    dim = units.LENGTH
    doc = ("margin to running a red light: while a light that governs the actor's lane is red, "
           "the distance of its front bumper to the stop line, negative once it crosses it (until "
           "30 m past it); 100 m when no red light is ahead within 100 m [m]")


@SIGNALS.register
class StopSign(SignalSpec):
    keyword = "stop_sign"
    dim = units.LENGTH
    doc = ("margin to running a stop sign of the map: the distance of the actor's front bumper to the "
           "line of the next stop sign that governs its lane and that it has not stopped for (below "
           "0.1 m/s with its front within 4 m before the line), negative once it crosses such a line "
           "without stopping (until 30 m past it); 100 m when none is ahead within 100 m [m]")
