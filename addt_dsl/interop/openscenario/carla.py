"""CARLA ScenarioRunner's conventions: its left-handed frame (a FileHeader description starting
with 'CARLA:') and its `criteria_*` pass criteria, which become oracles."""

from addt_dsl import expr as E
from addt_dsl.compiler.rules.oracles import NO_CLAUSES, stay_in_lane_formula
from addt_dsl.expr import eval_param_expr
from addt_dsl.plan import ActorPlan, OraclePlan


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
            param = cond.find("ByValueCondition/ParameterCondition")
            raw = param.get("value", "") if param is not None else ""
            try:
                arg = float(self.resolve(raw)) if raw.strip() else None
            except (KeyError, SyntaxError, ValueError, ArithmeticError):
                arg = None
            oracle = self.criterion(test, arg, ego, cond)
            if oracle is not None:
                found.setdefault(oracle.name, oracle)
        self.criteria = bool(found)
        return list(found.values())

    def criterion(self, test: str, arg: float | None, ego: ActorPlan, cond) -> OraclePlan | None:
        always, signal = (lambda f: E.Temporal(op="always", lo_s=0.0, hi_s=None, arg=f)), E.Signal
        if test == "CollisionTest":
            return OraclePlan(name="no_collision", formula=NO_CLAUSES["collision"]("ego", None), text="no collision")
        if test == "RunningRedLightTest":
            return OraclePlan(name="no_red_light", formula=NO_CLAUSES["red_light"]("ego", None), text="no red_light")
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
        why = {"RunningStopTest": "the twin has no stop signs",
               "WrongLaneTest": "no signal gives the driving direction of the lane the ego is in",
               "OnSidewalkTest": "no signal gives the type of the lane the ego is in"}.get(test, "no such oracle")
        self.skip(cond, f"criteria_{test} is not translated: {why}",
                  "translated: CollisionTest, RunningRedLightTest, KeepLaneTest, DrivenDistanceTest, MaxVelocityTest")
        return None
