"""Lateral actions: lane changes."""

from addt_dsl import expr as E
from addt_dsl.interop.openscenario.registry import ACTIONS
from addt_dsl.interop.openscenario.xml import only_child
from addt_dsl.plan import ClausePlan


class Lateral:
    @ACTIONS.register("LaneChangeAction", "approx", "`lane_change` over a time exactly; over a distance or at "
                      "a rate, the time at the speed then (W0802); a target lane relative to another entity: its "
                      "lane at the start (W0802)")
    def act_lane_change(self, change, who: str, act) -> ClausePlan | None:
        return self.lane_change(change, who, self.actors[who])

    def lane_change(self, change, who, info) -> ClausePlan | None:
        dyn, target = change.find("LaneChangeActionDynamics"), change.find("LaneChangeTarget")
        tgt = only_child(target)
        if tgt is None or dyn is None:
            self.error(change, "a lane change needs dynamics and a target")
            return None
        extra = {}
        shape = self.raw(dyn, "dynamicsShape", required=False)
        if shape in ("linear", "cubic", "sinusoidal", "step"):
            extra["shape"] = shape
        if tgt.tag == "RelativeTargetLane" and tgt.get("entityRef") not in (None, who) \
                and int(self.value(tgt, "value")) == 0:
            ref = self.actor_name(tgt)
            if ref is None:
                return None
            lane = self.actors[ref]["lane_now"] if ref in self.actors else None
            extra["to_lane_of"] = ref
        elif tgt.tag == "AbsoluteTargetLane":
            lane = int(self.value(tgt, "value"))
        else:
            ref = self.actor_name(tgt)
            if ref is None:
                return None
            base = self.actors[ref]["lane_now"] if ref != who else info["lane_now"]
            if base is None:
                self.skip(tgt, f"lane relative to {ref}, whose lane is not known (no translated position)")
                return None
            if ref != who:
                self.approx(tgt, f"lane relative to {ref}: its lane at the start ({base}), not at the change",
                            "`lane_change to_lane_of X` takes X's lane when the change starts (offset 0)")
            d = int(self.value(tgt, "value"))
            lane = base + d
            if base * lane <= 0 and d:
                lane += 1 if d > 0 else -1
        dim = self.raw(dyn, "dynamicsDimension")
        amount = abs(self.value(dyn, "value"))
        if dim == "time":
            duration = amount
        elif dim == "distance":
            duration = amount / max(info["speed_now"], 1.0)
            self.approx(dyn, f"a lane change over {amount:g} m: {duration:.3g} s at {info['speed_now']:.3g} m/s")
        else:
            duration = 3.5 / max(amount, 0.1)
            self.approx(dyn, f"a lane change at a lateral rate: {duration:.3g} s for a 3.5 m lane")
        info["lane_now"] = lane
        if "to_lane_of" in extra:
            return ClausePlan(keyword="behavior", name="lane_change",
                              settings={"duration": E.Num(value=max(duration, 0.5)), **extra})
        return ClausePlan(keyword="behavior", name="lane_change",
                          settings={"to": E.Num(value=float(lane)), "duration": E.Num(value=max(duration, 0.5)),
                                    **extra})
