"""Conditions: by value and by entity, as formulas over the language's signals."""

from addt_dsl import expr as E
from addt_dsl import units
from addt_dsl.expr import eval_param_expr
from addt_dsl.interop.openscenario.params import EXPR, all_of, any_of, plus_expr
from addt_dsl.interop.openscenario.registry import ENTITY_CONDITIONS, VALUE_CONDITIONS
from addt_dsl.interop.openscenario.xml import child_at, only_child
from addt_dsl.plan import LIGHT_STATES
from addt_dsl.road.lanes import DRIVING_TYPES
from addt_dsl.road.route import RouteError, resolve_route

EDGES = {"none": None, "rising": "rising", "falling": "falling", "risingOrFalling": "changing"}
RULE_OPS = {"lessThan": "<", "lessOrEqual": "<=", "greaterThan": ">", "greaterOrEqual": ">=", "equalTo": "==",
            "notEqualTo": "!="}


STAND_STILL_MS = 1e-3  # esmini: an entity below this speed [m/s] stands still (ScenarioEngine.cpp)


def sig(fn: str, *args: str):
    """A signal by its canonical name: `fn(A,B)`."""
    return E.Signal(name=f"{fn}({','.join(args)})")


VALUE_CONDITIONS.declare("SimulationTimeCondition", "exact", "a step's `at` time (one condition group, greater "
                         "than); as a stop trigger the run's duration; other uses refused")
VALUE_CONDITIONS.declare("StoryboardElementStateCondition", "approx", "another event's or action's start, run or "
                         "end (`after`, `when started/ended(A.step)`; running: started and not ended); an event of "
                         "teleports that do nothing here: the state that starts it; its own act or story running: "
                         "always true")
for _name, _note in (
        ("TimeOfDayCondition", "the twin has no time of day"),
        ("UserDefinedValueCondition", "a user-defined value means nothing to the twin"),
):
    VALUE_CONDITIONS.declare(_name, "refused", _note)
for _name, _note in (
        ("AngleCondition", "the language has no heading signal"),
        ("RelativeAngleCondition", "the language has no relative heading signal"),
):
    ENTITY_CONDITIONS.declare(_name, "refused", _note)


class Conditions:
    def condition(self, cond, who: str):
        """One <Condition> as a formula over signals, or None after a diagnostic."""
        value_cond = only_child(cond.find("ByValueCondition")) if cond.find("ByValueCondition") is not None else None
        if value_cond is not None:
            translate = VALUE_CONDITIONS.translator(value_cond.tag)
            if translate is not None:
                return translate(self, value_cond, who)
            self.skip(value_cond, f"<{value_cond.tag}> is not translated")
            return None
        by_entity = cond.find("ByEntityCondition")
        entity = only_child(child_at(by_entity, "EntityCondition"))
        if by_entity is None or entity is None:
            self.error(cond, "a condition needs a ByValueCondition or a ByEntityCondition")
            return None
        triggering = by_entity.find("TriggeringEntities")
        rule = triggering.get("triggeringEntitiesRule", "any") if triggering is not None else "any"
        actors = [self.actor_name(r) for r in by_entity.iterfind("TriggeringEntities/EntityRef")]
        if not actors or any(a is None for a in actors):
            return None
        parts = [self.entity_condition(entity, a) for a in actors]
        if any(p is None for p in parts):
            return None
        return all_of(parts) if rule == "all" else any_of(parts)

    @VALUE_CONDITIONS.register("ParameterCondition", "exact", "on a number parameter that a ParameterAction's "
                               "SetAction sets in an event: `var(P) OP V` (a scenario variable); an export's "
                               "placeholder: the formula in its side file; others refused (the parameter is "
                               "constant)")
    def cond_parameter(self, value_cond, who: str):
        ref = self.raw(value_cond, "parameterRef")
        exact = (self.sidecar or {}).get("conditions", {}).get(ref)
        if exact:
            return EXPR.validate_python(exact["formula"])
        if any(a.get("parameterRef") == ref for a in self.doc.iterfind(".//Story//GlobalAction/ParameterAction")):
            return self.variable_condition(value_cond, ref)
        self.skip(value_cond, f"<{value_cond.tag}> is not translated",
                  "a condition on a parameter that a ParameterAction sets is (a scenario variable)")
        return None

    @VALUE_CONDITIONS.register("VariableCondition", "exact", "`var(V) OP X` on a number variable")
    def cond_variable(self, value_cond, who: str):
        return self.variable_condition(value_cond, self.raw(value_cond, "variableRef"))

    def variable_condition(self, c, ref: str):
        """`var(NAME) OP value`: a scenario variable against a number."""
        op = RULE_OPS.get(c.get("rule", ""))
        name = self.variable(ref, c)
        if name is None:
            return None
        if op is None:
            self.error(c, f"rule \"{c.get('rule')}\" is not one of {', '.join(RULE_OPS)}")
            return None
        return E.Binary(op=op, left=sig("var", name), right=E.Num(value=self.value(c, "value")))

    @VALUE_CONDITIONS.register("TrafficSignalCondition", "exact", "`light(C) == S`: the state of the signal's "
                               "controller")
    @VALUE_CONDITIONS.register("TrafficSignalControllerCondition", "exact", "`light(C) == S`: the controller's phase")
    def cond_light(self, c, who: str):
        return self.light_condition(c)

    def light_condition(self, c):
        """`light(C) == S`: a signal's state (its controller's) or a controller's phase."""
        if c.tag == "TrafficSignalCondition":
            sid = self.raw(c, "name")
            ctl = self.light_controller(sid, c)
            state = self.signal_state(sid, self.raw(c, "state"), c) if ctl else None
        else:
            raw, phase = self.raw(c, "trafficSignalControllerRef"), self.raw(c, "phase")
            ctl = self.ctl_names.get(raw, raw)
            if ctl not in self.light_ctls or self.light_ctls[ctl].get("solo"):
                self.error(c, f"no traffic signal controller '{raw}'")
                return None
            state = self.light_ctls[ctl]["phases"].get(phase)
            if state is None:
                self.error(c, f"controller '{ctl}' has no phase '{phase}'",
                           f"phases: {', '.join(self.light_ctls[ctl]['phases'])}")
        if state is None:
            return None
        return E.Binary(op="==", left=E.Signal(name=f"light({ctl})"), right=E.Num(value=LIGHT_STATES[state]))

    @ENTITY_CONDITIONS.register("StandStillCondition", "approx", "`speed(A) < 0.001 m/s` (esmini's standstill "
                                "threshold) held for the duration (`for D`); beside other conditions or entities "
                                "the hold covers them all (W0802)")
    def cond_stand_still(self, c, a: str):
        # The hold is the step's (`when C for D`): `start` and `end_trigger` collect it.
        self.stand_still.append((self.value(c, "duration", units.TIME), c))
        return E.Binary(op="<", left=sig("speed", a), right=E.Num(value=STAND_STILL_MS))

    def stand_still_hold(self, since: int, conditions: int):
        """The hold [s] of the StandStillConditions read since index `since` of a trigger of
        `conditions` conditions in all (None: none); approximate unless it is the only one."""
        found = self.stand_still[since:]
        if not found:
            return None
        hold = max(d for d, _ in found)
        if conditions > 1 or len(found) > 1:
            self.approx(found[0][1], f"a standstill of {hold:g} s beside other conditions or entities: the whole "
                                     "condition must hold that long")
        return E.Num(value=hold)

    def entity_condition(self, c, a: str):
        translate = ENTITY_CONDITIONS.translator(c.tag)
        if translate is not None:
            return translate(self, c, a)
        self.skip(c, f"<{c.tag}> is not translated",
                  "translated: traveled distance, speed, acceleration, relative distance, time headway, TTC, "
                  "reach position, end of road")
        return None


    @ENTITY_CONDITIONS.register("TraveledDistanceCondition", "exact",
                                "`s(A)` from the actor's start station, in its own frame")
    def cond_traveled(self, c, a: str):
        # `s(A)` grows in A's driving direction, from its station in its own frame
        # (the road's station along +s; on a path, from the path's entry end).
        travelled = self.number(c, "value", units.LENGTH)
        since = getattr(self, "events_travel", None)  # CARLA: an event's distance counts from its act's start
        if since is not None:
            if since[0] == a:
                travelled = plus_expr(travelled, E.Num(value=since[1]))
            else:
                self.approx(c, f"a distance {a} travels in an event of an act that starts on {since[0]}'s: "
                               "counted from the run's start (ScenarioRunner: from the act's start)")
        return E.Binary(op=">=", left=sig("s", a), right=plus_expr(self.start_station(a), travelled))

    @ENTITY_CONDITIONS.register("SpeedCondition", "exact",
                                "`speed(A)` against the value")
    def cond_speed(self, c, a: str):
        op = RULE_OPS.get(c.get("rule", ""), ">")
        return E.Binary(op=op, left=sig("speed", a), right=self.number(c, "value", units.SPEED))

    @ENTITY_CONDITIONS.register("OffroadCondition", "approx",
                                "`road_edge(A) < 0 m for D` (off the road's lanes of any type but none, as "
                                "esmini measures it, for the duration); in a start trigger of one condition, "
                                "else refused; an entity off the road for D already when the event is armed "
                                "starts it D later (esmini: never, its rising edge has passed) (W0802)")
    def cond_offroad(self, c, a: str):
        duration = self.held(c, "an off-road duration")
        if duration is None:
            return None
        if duration > 0:
            self.approx(c, f"off the road for {duration:g} s: `for {duration:g} s` counts from the event's arming "
                           "(esmini's rising edge never fires for an entity off the road that long already)")
        return E.Binary(op="<", left=sig("road_edge", a), right=E.Num(value=0.0))

    def held(self, c, what: str) -> float | None:
        """The condition's `duration` [s], held as `for D` where it is positive; None (refused)
        where a hold cannot be translated: outside a start trigger of one condition."""
        duration = self.value(c, "duration", units.TIME)
        if duration > 0:
            if not getattr(self, "hold_allowed", False):
                self.skip(c, f"{what} is translated in a start trigger of one condition only")
                return None
            self.cond_hold = duration
        return duration

    @ENTITY_CONDITIONS.register("EndOfRoadCondition", "exact",
                                "`road_end(A) <= 0 m for D`: held at the end of its road (the importer sets "
                                "`at_road_end stop` on every scripted actor, as esmini stops its entities there) "
                                "for the duration; with a duration, in a start trigger of one condition, else "
                                "refused")
    def cond_end_of_road(self, c, a: str):
        duration = self.held(c, "an end-of-road duration")
        if duration is None:
            return None
        if duration > 0:
            self.cond_hold_edge = True  # (esmini: an edge of the held condition)
        return E.Binary(op="<=", left=sig("road_end", a), right=E.Num(value=0.0))

    @ENTITY_CONDITIONS.register("CollisionCondition", "approx",
                                "a collision of the actor with any other; with one entity or a type among several "
                                "others W0802")
    def cond_collision(self, c, a: str):
        # The twin ends a run at its first collision; as a condition, an overlap of the
        # actor's box with any other (exact with one other actor or a type that is every one).
        others = [n for n in self.actors if n != a]
        target = c.find("EntityRef")
        if target is not None and len(others) > 1:
            self.approx(c, "a collision with one entity: a collision of the actor with any other")
        elif c.find("ByType") is not None and len(others) > 1:
            self.approx(c, "a collision with a type of object: a collision of the actor with any other")
        return E.Binary(op="<=", left=sig("clearance", a), right=E.Num(value=0.0))

    @ENTITY_CONDITIONS.register("RelativeSpeedCondition", "approx",
                                "`rel_speed(A, B)`; longitudinal: the difference of the speeds (W0802); lateral "
                                "refused")
    def cond_relative_speed(self, c, a: str):
        op = RULE_OPS.get(c.get("rule", ""), ">")
        b = self.actor_name(c)
        if b is None:
            return None
        if c.get("direction") not in (None, "longitudinal"):
            self.skip(c, f"a {c.get('direction')} relative speed is not translated (longitudinal is)")
            return None
        if c.get("direction") == "longitudinal":
            self.approx(c, "a longitudinal relative speed: the difference of the speeds (the same when they "
                           "drive the same way)")
        return E.Binary(op=op, left=sig("rel_speed", a, b), right=self.number(c, "value", units.SPEED))

    @ENTITY_CONDITIONS.register("AccelerationCondition", "exact",
                                "`accel(A)` against the value")
    def cond_acceleration(self, c, a: str):
        op = RULE_OPS.get(c.get("rule", ""), ">")
        return E.Binary(op=op, left=sig("accel", a), right=self.number(c, "value", units.ACCELERATION))

    @ENTITY_CONDITIONS.register("RelativeClearanceCondition", "exact", "no other actor in the lanes "
                                "`from`..`to` of the actor's lane id (same side of the reference line) "
                                "within `distanceBackward`..`distanceForward` along s, and such a driving "
                                "lane there, as esmini (`lane_id`, `s`); every actor on one road without "
                                "a route; free space, opposite lanes and several lane ranges refused")
    def cond_clearance(self, c, a: str):
        ranges = list(c.iterfind("RelativeLaneRange"))
        if (c.get("freeSpace") or "false").lower() == "true" or (c.get("oppositeLanes") or "false").lower() == "true" \
                or len(ranges) != 1 or ranges[0].get("from") is None or ranges[0].get("to") is None:
            self.skip(c, "a clearance in free space, over opposite lanes, or without one lane range with `from` "
                         "and `to` is not translated")
            return None
        low, high = int(self.value(ranges[0], "from")), int(self.value(ranges[0], "to"))
        refs = [self.actor_name(r) for r in c.iterfind("EntityRef")]
        if None in refs:
            return None
        others = refs or [w for w in self.actors if w != a]
        road = self.placed[a].road
        if any(self.placed[w].road != road or self.actors[w].get("route_el") is not None
               or self.actors[w].get("against_s") for w in [a, *others]):
            self.skip(c, "a clearance among actors on several roads, on routes or driving against s is not "
                         "translated (stations along one road are)")
            return None
        forward, backward = self.number(c, "distanceForward", units.LENGTH), \
            self.number(c, "distanceBackward", units.LENGTH)
        lane, s = sig("lane_id", a), sig("s", a)
        # The area exists: a driving lane of the same side within the range, at the actor's s
        # (intervals of the road's lane sections, for each lane the actor may be in).
        odr = self.network.road(next(i for i, r in self.roads.items() if r.name == road))
        cases = []
        for sec in odr.sections:
            ids = {lane.id for lane in sec.left + sec.right if lane.type in DRIVING_TYPES}  # (a lane 0 m wide too)
            for own in sorted(ids):
                if any((own + k) in ids and (own + k) * own > 0 for k in range(low, high + 1)):
                    cases.append(all_of([E.Binary(op="==", left=lane, right=E.Num(value=float(own))),
                                         E.Binary(op=">=", left=s, right=E.Num(value=round(sec.s0, 9)))]
                                        + ([E.Binary(op="<", left=s, right=E.Num(value=round(sec.s1, 9)))]
                                           if sec.s1 < odr.length else [])))
        if not cases:
            return E.Binary(op="<", left=E.Num(value=1.0), right=E.Num(value=0.0))  # never
        parts = [any_of(cases)]
        for w in others:  # and none of the others in that area
            dl = E.Binary(op="-", left=sig("lane_id", w), right=lane)
            ds = E.Binary(op="-", left=sig("s", w), right=s)
            parts.append(E.Unary(op="not", arg=all_of([
                E.Binary(op=">=", left=dl, right=E.Num(value=float(low))),
                E.Binary(op="<=", left=dl, right=E.Num(value=float(high))),
                E.Binary(op=">", left=E.Binary(op="*", left=sig("lane_id", w), right=lane), right=E.Num(value=0.0)),
                E.Binary(op=">=", left=ds, right=E.Num(value=-backward.value) if isinstance(backward, E.Num)
                         else E.Unary(op="neg", arg=backward)),
                E.Binary(op="<=", left=ds, right=forward)])))
        return all_of(parts)

    @ENTITY_CONDITIONS.register("RelativeDistanceCondition", "approx",
                                "longitudinal and cartesian between entities (free space: W0802); TTC with a position "
                                "and lateral distances refused")
    @ENTITY_CONDITIONS.register("TimeToCollisionCondition", "approx", "see RelativeDistanceCondition")
    @ENTITY_CONDITIONS.register("TimeHeadwayCondition", "approx", "see RelativeDistanceCondition")
    def cond_relative_distance(self, c, a: str):
        op = RULE_OPS.get(c.get("rule", ""), ">")
        target = c.find("TimeToCollisionConditionTarget/EntityRef") if c.tag == "TimeToCollisionCondition" else c
        if target is None:
            self.skip(c, "time to collision with a position is not translated (with an entity it is)")
            return None
        b = self.actor_name(target)
        if b is None:
            return None
        # freespace="false": distances between the entities' reference points (the
        # importer places an actor's centre there), i.e. the bumper gap plus half of
        # both lengths along the road.
        free = (c.get("freespace") or "false").lower() == "true"
        half = 0.0 if free else 0.5 * (self.size(a)[0] + self.size(b)[0])
        if c.tag == "TimeToCollisionCondition":
            # As esmini evaluates it: the longitudinal distance along the road over the
            # speed difference; undefined (the condition false, whatever its rule) when
            # they do not close in.
            value = self.number(c, "value", units.TIME)
            closing = E.Binary(op="-", left=sig("speed", a), right=sig("speed", b))
            lhs = plus_expr(sig("gap", a, b), E.Num(value=half)) if half else sig("gap", a, b)
            if free and c.get("coordinateSystem") == "entity" and c.get("relativeDistanceType") == "longitudinal":
                # In a's coordinates: the boxes' gap along a's heading (esmini's boxes sit
                # their centre's x ahead of the reference point, where the actors' are).
                lhs = sig("lon_gap", a, b)
                shift = round(self.actors[b].get("box_x_m", 0.0) - self.actors[a].get("box_x_m", 0.0), 9)
                if shift:
                    lhs = E.Binary(op="+" if shift > 0 else "-", left=lhs, right=E.Num(value=abs(shift)))
                self.approx(c, "time to collision in entity coordinates: the closing speed is the speed "
                               "difference (esmini: the first's velocity along the second's direction of "
                               "motion less the second's speed, the same while they move alike)")
            return all_of([E.Binary(op=">", left=closing, right=E.Num(value=0.0)),
                         E.Binary(op=op, left=lhs, right=E.Binary(op="*", left=value, right=closing))])
        if c.tag == "TimeHeadwayCondition":
            headway = E.Binary(op="*", left=self.number(c, "value", units.TIME), right=sig("speed", a))
            return E.Binary(op=op, left=sig("gap", a, b),
                            right=plus_expr(headway, E.Num(value=-half)) if half else headway)
        kind = c.get("relativeDistanceType", "cartesianDistance")
        free = (c.get("freespace") or "false").lower() == "true"
        value = self.number(c, "value", units.LENGTH)
        if kind == "longitudinal":
            # esmini compares the absolute distance, whichever is ahead (an overtake passes
            # through 0): |gap(a, b) + half of both lengths| between reference points; free
            # space, that less the half lengths.
            half = 0.5 * (self.size(a)[0] + self.size(b)[0])
            left = E.Call(fn="abs", args=(plus_expr(sig("gap", a, b), E.Num(value=half)),))
            return E.Binary(op=op, left=left, right=plus_expr(value, E.Num(value=half)) if free else value)
        if kind in ("cartesianDistance", "euclidianDistance"):
            if free:
                self.approx(c, "a free-space distance: the centre distance less half of both lengths")
                half = 0.5 * (self.size(a)[0] + self.size(b)[0])
                return E.Binary(op=op, left=sig("distance", a, b), right=plus_expr(value, E.Num(value=half)))
            return E.Binary(op=op, left=sig("distance", a, b), right=value)
        self.skip(c, f"a {kind} relative distance is not translated (longitudinal and cartesian are)")
        return None

    @ENTITY_CONDITIONS.register("ReachPositionCondition", "approx",
                                "the Euclidean distance to the position's point (an Orientation in it is not "
                                "checked: W0802); longitudinal along the actor's own road; free space and other "
                                "kinds refused")
    @ENTITY_CONDITIONS.register("DistanceCondition", "approx", "see ReachPositionCondition")
    def cond_distance_to_position(self, c, a: str):
        op = RULE_OPS.get(c.get("rule", ""), ">")
        # The Euclidean distance of the entity's reference point to the position's point
        # (esmini: `dist < tolerance`; DistanceCondition: its rule against `value`).
        pos = c.find("Position")
        if pos is None:
            self.error(c, f"<{c.tag}> needs a <Position>")
            return None
        point = self.world_point(pos, a)
        if point is None:
            return None
        x, y, _ = point
        if c.tag == "ReachPositionCondition":
            radius, op = self.number(c, "tolerance", units.LENGTH), "<"
            if pos.find("*/Orientation") is not None:
                self.approx(pos.find("*/Orientation"), "the position's Orientation: esmini also requires the "
                                                       "entity's heading, pitch and roll within 0.05 rad of it; "
                                                       "here the distance alone")
        else:
            radius = self.number(c, "value", units.LENGTH)
            if (c.get("freespace") or "false").lower() == "true":
                self.skip(c, "a free-space distance to a position is not translated (between reference points "
                             "it is)")
                return None
            kind = c.get("relativeDistanceType", "cartesianDistance")
            lane_pos = only_child(pos)
            if kind == "longitudinal" and lane_pos is not None and \
                    lane_pos.tag in ("LanePosition", "RoadPosition") and self.along_s(a) and \
                    self.placed[a].road == self.road(self.raw(lane_pos, "roadId"), lane_pos):
                # along the road both are on: the stations' difference
                gap = E.Call(fn="abs", args=[E.Binary(op="-", left=sig("s", a),
                                                      right=self.number(lane_pos, "s", units.LENGTH))])
                return E.Binary(op=op, left=gap, right=radius)
            if kind not in ("cartesianDistance", "euclidianDistance"):
                self.skip(c, f"a {kind} distance to a position is not translated (cartesian is, and "
                             "longitudinal along the actor's own road)")
                return None
        dx = E.Binary(op="-", left=sig("x", a), right=E.Num(value=round(x, 9)))
        dy = E.Binary(op="-", left=sig("y", a), right=E.Num(value=round(y, 9)))
        square = E.Binary(op="+", left=E.Binary(op="*", left=dx, right=dx), right=E.Binary(op="*", left=dy, right=dy))
        return E.Binary(op=op, left=square, right=E.Binary(op="*", left=radius, right=radius))

    def start_station(self, who: str):
        """The actor's first `s(A)` as an expression: its road station where it drives a road
        along +s; on a path (a lane driven against s, a reversed lane, a route), the
        distance from the path's entry end, as the runtime measures it."""
        return self.frame_station(who, self.placed[who].s)

    def frame_station(self, who: str, s):
        """A station `s` of the actor's first road as `s(A)` measures it (see start_station)."""
        at = self.placed[who]
        road_name, lane, s_start = at.road, at.lane, at.s
        road_id = next(i for i, r in self.roads.items() if r.name == road_name)
        info = self.actors[who]
        reverse = bool(info.get("against_s")) and info["vehicle"] != "obstacle"
        routed = info.get("route_el") is not None or info.get("route_from_position") is not None
        if lane == 0 or (not routed and self.along_s(who)):
            return s
        try:
            _, legs = resolve_route(self.network, [road_id], lane,
                                    float(eval_param_expr(s_start, self.param_values())), reverse=reverse)
        except (RouteError, ValueError, ArithmeticError):
            return s
        first = legs[0]
        entry = E.Num(value=round(float(first.s_from), 9))
        return E.Binary(op="-", left=s, right=entry) if first.direction > 0 else \
            E.Binary(op="-", left=entry, right=s)

    def driving_way(self, who: str) -> int:
        """+1 if the actor starts driving towards +s of its road, -1 against."""
        road_name, lane = self.placed[who].road, self.placed[who].lane
        if lane == 0:
            return 1
        road_id = next(i for i, r in self.roads.items() if r.name == road_name)
        reverse = bool(self.actors[who].get("against_s")) and self.actors[who]["vehicle"] != "obstacle"
        return self.network.road(road_id).travel_direction(lane) * (-1 if reverse else 1)

    def along_s(self, who: str) -> bool:
        """Whether the actor drives towards +s (its lane's OpenDRIVE direction)."""
        road_name, lane = self.placed[who].road, self.placed[who].lane
        road_id = next(i for i, r in self.roads.items() if r.name == road_name)
        way = -1 if self.actors[who].get("against_s") and self.actors[who]["vehicle"] != "obstacle" else 1
        return lane == 0 or self.network.road(road_id).travel_direction(lane) * way > 0
