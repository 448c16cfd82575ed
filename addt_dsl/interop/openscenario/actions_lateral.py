"""Lateral actions: lane changes."""

from addt_dsl import expr as E
from addt_dsl.interop.openscenario.registry import ACTIONS
from addt_dsl.interop.openscenario.xml import only_child
from addt_dsl.specs.behaviors import lanes_over
from addt_dsl.plan import ClausePlan


class Lateral:
    @ACTIONS.register("LaneChangeAction", "approx", "`lane_change` over a time exactly; over a distance or at "
                      "a rate, the time at the speed then (W0802); a target lane relative to another entity: its "
                      "lane when the change starts (`to_lane_of X lanes N`)")
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
        ref = self.actor_name(tgt) if tgt.tag == "RelativeTargetLane" and tgt.get("entityRef") else who
        if ref is None:
            return None
        if ref != who:
            # Another actor's lane when the change starts, `value` lanes to its driver's left.
            d = int(self.value(tgt, "value"))
            lane = self.actors[ref]["lane_now"] if ref in self.actors else None
            if lane is not None and d:  # where it is expected (a later change relative to its own lane)
                lane = lanes_over(lane, d)
            extra["to_lane_of"] = ref
            if d:
                extra["lanes"] = E.Num(value=float(d))
        elif tgt.tag == "AbsoluteTargetLane":
            lane = int(self.value(tgt, "value"))
        else:  # its own lane: where the importer expects it then
            base = info["lane_now"]
            if base is None:
                self.skip(tgt, f"lane relative to {who}, whose lane is not known (no translated position)")
                return None
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
