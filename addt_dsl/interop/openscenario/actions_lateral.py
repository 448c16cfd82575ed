"""Lateral actions: lane changes and lane offsets."""

from addt_dsl import expr as E
from addt_dsl import units
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
            # Positive is to the left of the way the actor drives (esmini: the lane id plus the
            # value for an entity heading along +s, minus it against s).
            d = int(self.value(tgt, "value")) * (self.driving_way(who) if who in self.placed else 1)
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

    @ACTIONS.register("LaneOffsetAction", "approx", "`lane_offset to O max_lat_accel A shape S` to an absolute "
                      "target: esmini's dynamics (the time from the shape's peak lateral acceleration, from the "
                      "offset the move starts at; ends at the offset); a positive value away from the road's "
                      "reference line, as esmini takes it (by the lane the importer tracks the actor in); "
                      "no maxLateralAcc: esmini's 0.5 m/s^2 (W0802); continuous: ends at the offset as in esmini "
                      "(W0802); a relative target is refused")
    def act_lane_offset(self, offset, who: str, act) -> ClausePlan | None:
        dyn, target = offset.find("LaneOffsetActionDynamics"), offset.find("LaneOffsetTarget")
        tgt = only_child(target)
        if dyn is None or tgt is None:
            self.error(offset, "a lane offset needs dynamics and a target")
            return None
        if tgt.tag != "AbsoluteTargetLaneOffset":
            self.skip(tgt, f"a <{tgt.tag}> is not translated (an absolute target is)")
            return None
        lane = self.actors[who]["lane_now"]
        if not lane:
            self.skip(tgt, f"a lane offset of {who}, whose lane is not known (no translated position)")
            return None
        shape = self.raw(dyn, "dynamicsShape")
        if shape not in ("linear", "cubic", "sinusoidal", "step"):
            self.error(dyn, f"dynamicsShape \"{shape}\" is not one of linear, cubic, sinusoidal, step")
            return None
        if dyn.get("maxLateralAcc") is None:
            accel = 0.5
            self.approx(dyn, "no maxLateralAcc: 0.5 m/s^2, esmini's default")
        else:
            accel = max(self.value(dyn, "maxLateralAcc", units.ACCELERATION), 0.01)
        if (offset.get("continuous") or "false").lower() in ("true", "1"):
            self.approx(offset, "a continuous lane offset: ends once at the offset, as esmini's does (it holds "
                                "the offset until another lateral action)")
        # esmini: the offset along t is the value times the sign of the lane id (toward the
        # right of the lane's driving direction for a positive value).
        to = self.value(tgt, "value", units.LENGTH) * (1.0 if lane > 0 else -1.0)
        return ClausePlan(keyword="behavior", name="lane_offset",
                          settings={"to": E.Num(value=to), "max_lat_accel": E.Num(value=accel),
                                    "shape": shape})
