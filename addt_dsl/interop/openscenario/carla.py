"""CARLA ScenarioRunner's conventions: its left-handed frame (a FileHeader description starting
with 'CARLA:'), its controllers that move an entity along its body heading, and its `criteria_*`
pass criteria, which become oracles."""

from addt_dsl import expr as E
from addt_dsl import units
from addt_dsl.compiler.rules.oracles import NO_CLAUSES, stay_in_lane_formula
from addt_dsl.expr import eval_param_expr
from addt_dsl.interop.openscenario.xml import child_at
from addt_dsl.plan import ActorPlan, ClausePlan, OraclePlan
from addt_dsl.registry import BEHAVIORS


class CarlaFrame:
    def mirror(self, value):
        """A lateral coordinate or a heading (y, t, an offset, h; a float or an expression) in
        OpenDRIVE's right-handed frame: negated in a CARLA-frame file, where y, t, lane offsets
        and yaw grow to the right (ScenarioRunner's `use_carla_coordinate_system`)."""
        if not self.carla:
            return value
        if isinstance(value, (int, float)):
            return -value
        if isinstance(value, E.Num):
            return E.Num(value=-value.value)
        return E.Unary(op="neg", arg=value)


# ScenarioRunner's controllers (srunner/scenariomanager/actorcontrols) that move an entity along
# its body heading when a speed action sets it moving without waypoints: PedestrianControl (the
# default for a walker, actor_control.py) gives the walker its forward vector and the target speed;
# VehicleLongitudinalControl only opens the throttle (no steering). The others follow the lanes
# (NpcVehicleControl, a vehicle's default, with CARLA's LocalPlanner; SimpleVehicleControl).
HEADING_CONTROLLERS = {"pedestrian_control": "PedestrianControl",
                       "vehicle_longitudinal_control": "VehicleLongitudinalControl"}
# The fastest `walk` (its spec's bound) [m/s].
WALK_MAX_SPEED_MS = next(p.high for p in BEHAVIORS.get("walk").params if p.name == "speed")
# A speed the controller sets at once: within one 0.01 s step up to 10 m/s [m/s^2].
AT_ONCE_ACCEL = 1000.0


class CarlaWalkers:
    carla_warned: frozenset[str] = frozenset()  # entities told how their speed changes differ

    def carla_controller(self, who: str) -> str | None:
        """The ScenarioRunner controller that moves `who` along its heading (a HEADING_CONTROLLERS
        value), or None (it follows its lane; not a CARLA-frame file): the `module` property of
        its Init AssignControllerAction, else ScenarioRunner's default for its kind."""
        if not self.carla or who == "ego":
            return None
        module = None
        for private in self.doc.iterfind("Storyboard/Init/Actions/Private"):
            if self.renames.get(private.get("entityRef")) != who:
                continue
            for prop in private.iterfind("PrivateAction/ControllerAction/AssignControllerAction/Controller/"
                                         "Properties/Property"):
                if prop.get("name") == "module":
                    module = prop.get("value")
        if module is None and self.actors[who]["vehicle"] == "pedestrian":
            module = "pedestrian_control"
        return HEADING_CONTROLLERS.get(module or "")

    def carla_walk(self, act, who: str) -> ClausePlan | None:
        """A SpeedAction on an entity a heading controller moves (`carla_controller`), as
        ScenarioRunner runs it (ChangeActorTargetSpeed, openscenario_parser.py): the target speed
        at once, whatever the dynamics' shape, along the body's heading (`walk` at the file's
        heading relative to the lane); the action completes after its `value` as a distance
        (dynamicsDimension distance) or as a time (any other dimension), and the entity keeps
        the speed. None: not such an action (the caller translates it as any other)."""
        controller = self.carla_controller(who)
        speed = act.find("SpeedAction")
        if controller is None or speed is None:
            return None
        info = self.actors[who]
        target = child_at(speed, "SpeedActionTarget", "AbsoluteTargetSpeed")
        if target is None or info.get("route_el") is not None or info.get("route_from_position") is not None:
            self.approx(speed, f"{who} moves along its lane: the ScenarioRunner controller {controller} moves "
                               "it along its heading (translated so for absolute target speeds without a route)")
            return None
        v = self.number(target, "value", units.SPEED)
        v_now = float(eval_param_expr(v, self.param_values()))
        if v_now > WALK_MAX_SPEED_MS:
            self.approx(speed, f"{who} moves along its lane: the ScenarioRunner controller {controller} moves "
                               f"it along its heading (translated so up to {WALK_MAX_SPEED_MS:g} m/s, `walk`)")
            return None
        info["speed_now"] = v_now
        heading = 0.0
        if info.get("heading") is not None:
            heading = self.heading_from_lane(info["heading"], self.placed[who], bool(info.get("against_s")))
        at_once = E.Num(value=AT_ONCE_ACCEL)
        settings = {"speed": v, "heading": E.Num(value=heading), "accel": at_once, "decel": at_once}
        dyn = speed.find("SpeedActionDynamics")
        if dyn is not None and dyn.get("value") is not None:
            if dyn.get("dynamicsDimension") == "distance":
                settings["distance"] = self.number(dyn, "value", units.LENGTH)
            else:
                settings["duration"] = self.number(dyn, "value", units.TIME)
        if controller == "VehicleLongitudinalControl" and who not in self.carla_warned:
            self.carla_warned = self.carla_warned | {who}  # once per entity: each speed action differs so
            self.approx(speed, f"{who} reaches the speed of each speed action at once: the ScenarioRunner "
                               f"controller {controller} opens the throttle below it and closes it above, "
                               "without braking (the speed then follows the vehicle physics of CARLA)")
        return ClausePlan(keyword="behavior", name="walk", settings=settings)


class CarlaCriteria:
    # -- pass criteria

    def pass_criteria(self, ego: ActorPlan) -> list[OraclePlan]:
        """CARLA ScenarioRunner's test criteria as oracles on the ego: the stop triggers'
        conditions named `criteria_<Test>` (a ParameterCondition whose value, if any, is the
        test's argument), as ScenarioRunner reads them. Those the language cannot judge are
        W0801; none at all: [] (the caller's default)."""
        found: dict[str, OraclePlan] = {}
        for cond in self.doc.iterfind("Storyboard//StopTrigger//Condition"):
            name = cond.get("name") or ""
            if not name.startswith("criteria_"):
                continue
            test = name[len("criteria_"):]
            oracle = self.criterion(test, self.criterion_argument(cond), ego, cond)
            if oracle is not None:
                found.setdefault(oracle.name, oracle)
        self.criteria = bool(found)
        return list(found.values())

    def criterion_argument(self, cond) -> float | None:
        """A criterion's argument: its ParameterCondition's value where the condition names a
        `parameterRef` (ScenarioRunner passes the value as the keyword argument so named, and
        nothing without one: openscenario_parser.py); None where it names none or the value
        does not resolve to a number."""
        param = cond.find("ByValueCondition/ParameterCondition")
        if param is None or not (param.get("parameterRef") or "").strip():
            return None
        raw = param.get("value", "")
        try:
            return float(self.resolve(raw)) if raw.strip() else None
        except (KeyError, SyntaxError, ValueError, ArithmeticError):
            return None

    def criterion(self, test: str, arg: float | None, ego: ActorPlan, cond) -> OraclePlan | None:
        always, signal = (lambda f: E.Temporal(op="always", lo_s=0.0, hi_s=None, arg=f)), E.Signal
        if test == "CollisionTest":
            return OraclePlan(name="no_collision", formula=NO_CLAUSES["collision"]("ego", None), text="no collision")
        if test == "RunningRedLightTest":
            if self.doc.find(".//TrafficSignalController") is None:
                self.approx(cond, f"criteria_{test} is translated as `no red_light`, which judges the lights of the "
                                  "file's TrafficSignalControllers: it declares none, so no light turns red in the "
                                  "twin (CARLA cycles the town's lights itself)")
            return OraclePlan(name="no_red_light", formula=NO_CLAUSES["red_light"]("ego", None), text="no red_light")
        if test == "RunningStopTest":
            self.approx(cond, f"criteria_{test} is translated as `no stop_sign`: the stop signs of the map's "
                              "OpenDRIVE (type 206) on the lanes of their own <validity> (<signalReference>s are "
                              "not read), stopped below 0.1 m/s within 4 m before the line; ScenarioRunner judges "
                              "CARLA's stop actors and their trigger volumes")
            return OraclePlan(name="no_stop_sign", formula=NO_CLAUSES["stop_sign"]("ego", None), text="no stop_sign")
        if test == "KeepLaneTest":
            road_id = next(i for i, r in self.roads.items() if r.name == ego.road)
            odr = self.network.road(road_id)
            s0 = min(max(float(eval_param_expr(ego.s, self.param_values())), 0.0), odr.length)
            formula = stay_in_lane_formula(float(odr.lane_width(int(ego.lane.value), s0)), ego.width_m)
            if formula is None:
                self.skip(cond, f"criteria_{test}: the ego is wider than its lane: not translated")
                return None
            self.approx(cond, f"criteria_{test} is translated as `stay in lane` (the body inside the lane); "
                              "ScenarioRunner fails it on any lane marking crossed")
            return OraclePlan(name="keep_lane", formula=formula, text="stay in lane")
        if test == "DrivenDistanceTest" and arg is not None and arg > 0:
            return OraclePlan(name="driven_distance", formula=E.Temporal(
                op="eventually", lo_s=0.0, hi_s=None,
                arg=E.Binary(op=">=", left=signal(name="travelled(ego)"), right=E.Num(value=arg))),
                text=f"eventually travelled(ego) >= {arg:g} m")
        if test == "MaxVelocityTest" and arg is not None and arg > 0:
            return OraclePlan(name="max_velocity", formula=always(E.Binary(
                op="<=", left=signal(name="speed(ego)"), right=E.Num(value=arg))),
                text=f"always speed(ego) <= {arg:g} m/s")
        if test == "WrongLaneTest":
            self.approx(cond, f"criteria_{test} is translated as `always not wrong_way(ego)`: the ego's centre in a "
                              "driving lane of its road or route whose traffic runs against the way it drives there, "
                              "outside junctions; ScenarioRunner fails it when the ego passes, outside a junction, "
                              "into a lane whose direction differs from the last one's by more than 150 deg, or "
                              "leaves a junction heading more than 120 deg off its lane, on the nearest lane of "
                              "any road")
            return OraclePlan(name="wrong_lane", formula=always(E.Unary(op="not", arg=signal(name="wrong_way(ego)"))),
                              text="always not wrong_way(ego)")
        if test == "OnSidewalkTest":
            return self.on_sidewalk(test, cond, always, signal)
        if test in ("DrivenDistanceTest", "MaxVelocityTest"):
            self.skip(cond, f"criteria_{test} is not translated: its ParameterCondition gives no positive value with "
                            "a parameterRef (ScenarioRunner passes the value only as the argument a parameterRef "
                            "names, and the test needs one)")
            return None
        self.skip(cond, f"criteria_{test} is not translated: no such oracle",
                  "translated: CollisionTest, RunningRedLightTest, RunningStopTest, KeepLaneTest, DrivenDistanceTest, "
                  "MaxVelocityTest, WrongLaneTest, OnSidewalkTest")
        return None

    def on_sidewalk(self, test: str, cond, always, signal) -> OraclePlan:
        """OnSidewalkTest(duration D): ScenarioRunner fails it once the ego's time off the lanes
        (`off_lanes`), summed over its stretches less each one's first tick, exceeds D; D is
        the condition's value where it names a parameterRef, else 0 s (openscenario_parser.py)."""
        limit = max(self.criterion_argument(cond) or 0.0, 0.0)
        off = signal(name="off_lanes(ego)")
        where = ("ScenarioRunner reads the nearest lane of any road, the twin the lanes of the ego's road or route "
                 "(its leg's road in a junction)")
        if limit == 0.0:
            self.approx(cond, f"criteria_{test} is translated as `always not off_lanes(ego)`: it fails at the first "
                              "sample off the lanes, ScenarioRunner at the second tick running (its time off them "
                              f"above 0 s); {where}")
            return OraclePlan(name="on_sidewalk", formula=always(E.Unary(op="not", arg=off)),
                              text="always not off_lanes(ego)")
        self.approx(cond, f"criteria_{test} {limit:g} s is translated as `always not (always within {limit:g} s "
                          f"off_lanes(ego))`: one stretch of {limit:g} s off the lanes fails it, where ScenarioRunner "
                          f"sums the stretches (each less its first tick) and fails above {limit:g} s; {where}")
        return OraclePlan(name="on_sidewalk", formula=always(E.Unary(op="not", arg=E.Temporal(
            op="always", lo_s=0.0, hi_s=limit, arg=off))),
            text=f"always not (always within {limit:g} s off_lanes(ego))")
