"""Teleport, synchronize and controller actions."""

import json
import math

from addt_dsl import expr as E
from addt_dsl.expr import eval_param_expr
from addt_dsl.interop.openscenario.params import EXPR
from addt_dsl.interop.openscenario.positions import Placement
from addt_dsl.interop.openscenario.registry import ACTIONS
from addt_dsl.interop.openscenario.sidefile import CONTROLLER_PREFIX
from addt_dsl.interop.openscenario.xml import child_at, first_of, only_child
from addt_dsl.plan import ClausePlan
from addt_dsl.registry import BEHAVIORS


def setting_of(value):
    if isinstance(value, str):
        return value
    if isinstance(value, dict):  # a live expression (`speed 2 * speed(ego) - 1 m/s`), as the export writes it
        return EXPR.validate_python(value)
    if isinstance(value, list):
        return [E.Num(value=float(v)) for v in value]
    return E.Num(value=float(value))


class Misc:
    @ACTIONS.register("TeleportAction", "approx", "to a lane or road position on the road the actor drives "
                      "(others refused); it keeps facing its lane (another heading: W0802)")
    def act_teleport(self, act, who: str, wrapper) -> ClausePlan | None:
        return self.teleport(act, who)

    @ACTIONS.register("SynchronizeAction", "approx", "`synchronize` (with a final speed: esmini's speed "
                      "profile); a steady state refused; an own target point across the road: headed for "
                      "straight (W0802)")
    def act_synchronize(self, act, who: str, wrapper) -> ClausePlan | None:
        return self.synchronize(act, who)

    @ACTIONS.register("ActivateControllerAction", "approx", "the entity follows its actions, as under "
                      "OpenSCENARIO's default controller (esmini's driver models are not emulated; W0802)")
    def act_activate_controller(self, act, who: str, wrapper) -> None:
        self.approx(act, "a controller: the entity follows its actions, as under the default controller "
                         "of OpenSCENARIO (the driver models of esmini are not emulated)")
        return None

    @ACTIONS.register("ControllerAction", "approx", "a controller named addt_<behaviour> (addtc export): that "
                      "behaviour exactly; others: the entity follows its actions (W0802)")
    def act_controller(self, act, who: str, wrapper) -> ClausePlan | None:
        ctrl = act.find(".//Controller")
        if ctrl is not None and (ctrl.get("name") or "").startswith(CONTROLLER_PREFIX):
            keyword = ctrl.get("name")[len(CONTROLLER_PREFIX):]
            if keyword in BEHAVIORS:
                settings = {}
                for prop in ctrl.iterfind("Properties/Property"):
                    raw = prop.get("value", "")
                    if raw == "":
                        continue  # an empty setting is the default
                    try:
                        settings[prop.get("name")] = setting_of(json.loads(raw))
                    except ValueError:
                        settings[prop.get("name")] = raw
                return ClausePlan(keyword="behavior", name=keyword, settings=settings)
        self.approx(act, "a controller: the entity follows its actions, as under the default controller "
                         "of OpenSCENARIO (the driver models of esmini are not emulated)")
        return None

    def teleport(self, act, who: str) -> ClausePlan | None:
        """A TeleportAction during the run: to a lane or road position of the road the actor
        is on (`teleport s S t T`, road coordinates); to its own position moved only in
        height, nothing (the twin's actors follow the road's height)."""
        pos_el = act.find("Position")
        pos = only_child(pos_el) if pos_el is not None else None
        if pos is None:
            self.error(act, "a TeleportAction needs one <Position>")
            return None
        if pos.tag == "RelativeObjectPosition" and self.actor_name(pos) == who and \
                self.value(pos, "dx", default=0.0) == 0.0 and self.value(pos, "dy", default=0.0) == 0.0:
            self.approx(act, "a teleport that only raises or lowers the actor: nothing (actors follow the road's "
                             "height)")
            self.level_body(pos, who)
            return None
        if pos.tag in ("LanePosition", "RoadPosition"):
            road = self.road(self.raw(pos, "roadId"), pos)
            if road == self.placed[who].road and not self.actors[who].get("route_el"):
                got = self.road_point(pos_el, who)
                if got is None:
                    return None
                s_val, t_val = got
                odr = self.network.road(next(i for i, r in self.roads.items() if r.name == road))
                lane = odr.lane_at(s_val, t_val)
                target = Placement(road, lane, E.Num(value=s_val), E.Num(value=0.0)) if lane else None
                heading = self.file_heading(pos_el, target) if target is not None else None
                if heading is not None and abs(self.heading_from_lane(heading, target, False)) > 1e-9:
                    self.approx(pos.find("Orientation"), f"{who}'s heading after the teleport: its lane's driving "
                                                         "direction (`teleport` moves, it does not turn)")
                return ClausePlan(keyword="behavior", name="teleport",
                                  settings={"s": E.Num(value=round(s_val, 9)), "t": E.Num(value=round(t_val, 9))})
        self.skip(act, f"a teleport to a <{pos.tag}> is not translated",
                  "a lane or road position on the road the actor drives (without a route) is")
        return None

    def synchronize(self, act, who: str) -> ClausePlan | None:
        master = self.actor_name(act, "masterEntityRef")
        if master is None:
            return None
        master_pos = self.position(first_of(act.find("TargetPositionMaster"), act), master)
        own = self.road_point(first_of(act.find("TargetPosition"), act), who)
        if master_pos is None or own is None:
            return None
        # Stations as `s(A)` measures them: along each actor's own path (a lane driven
        # against s, a route: from the path's entry end).
        settings = {"master": master, "master_at": self.frame_station(master, master_pos.s)
                    if master_pos.road == self.placed[master].road else master_pos.s,
                    "target_s": self.frame_station(who, E.Num(value=round(own[0], 9))),
                    "target_t": E.Num(value=round(own[1], 9))}
        at = self.placed[who]
        road, lane, s0, off0 = at.road, at.lane, at.s, at.offset
        params = self.param_values()
        road_id = next(i for i, r in self.roads.items() if r.name == road)
        s0_val = float(eval_param_expr(s0, params))
        try:
            t0 = self.network.road(road_id).lane_center_t(lane, s0_val) + float(eval_param_expr(off0, params))
        except ValueError:  # placed where the road has no such lane (reported with the position)
            t0 = own[1]
        if abs(own[1] - t0) > 0.5 and self.along_s(who):
            # Across the road: head for the point (the language's synchronize moves along a heading).
            settings["heading"] = E.Num(value=round(math.atan2(own[1] - t0, own[0] - s0_val), 9))
            self.approx(act, f"{who} heads straight for its target point from where it starts")
        for attr, key in (("targetTolerance", "tolerance"), ("targetToleranceMaster", "master_tolerance")):
            if act.get(attr) is not None:
                settings[key] = E.Num(value=self.value(act, attr))
        final = child_at(act, "FinalSpeed", "AbsoluteSpeed")
        relative = child_at(act, "FinalSpeed", "RelativeSpeedToMaster")
        for steady in act.iterfind("FinalSpeed/*/*"):
            self.skip(steady, f"a <{steady.tag}> (a final stretch at the final speed) is not translated")
            return None
        if final is not None:
            settings["final_speed"] = E.Num(value=self.value(final, "value"))
        elif relative is not None:
            # esmini reads the master's speed at every step (a continuous relative target).
            other, value = E.Signal(name=f"speed({master})"), self.value(relative, "value")
            if relative.get("speedTargetValueType", "delta") == "factor":
                settings["final_speed"] = E.Binary(op="*", left=E.Num(value=value), right=other)
            else:
                settings["final_speed"] = E.Binary(op="+" if value >= 0.0 else "-", left=other,
                                                   right=E.Num(value=abs(value)))
        if act.find("TargetPositionMaster/LanePosition") is None and act.find("TargetPositionMaster") is not None:
            self.approx(act.find("TargetPositionMaster"), "the master's target point: its station on its road")
        return ClausePlan(keyword="behavior", name="synchronize", settings=settings)
