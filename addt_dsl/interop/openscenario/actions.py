"""Private actions: the dispatch of an action element to its registered translation."""

import json



from addt_dsl.interop.openscenario.sidefile import CONTROLLER_PREFIX
from addt_dsl.plan import (ClausePlan)
from addt_dsl.registry import BEHAVIORS
from addt_dsl.interop.openscenario.xml import child_at
from addt_dsl.interop.openscenario.xml import first_of
from addt_dsl.interop.openscenario.xml import only_child
from addt_dsl.interop.openscenario.actions_misc import setting_of


class Actions:
    # -- actions

    def private_action(self, act, who: str):
        """The behaviour clause an action starts, or None after a diagnostic."""
        if who == "ego" and not self.scripted_ego:
            self.approx(act, f"<{act.tag}> on the ego: the stack under test drives the ego",
                        "`addtc import --ego scripted` makes the ego follow the file's actions")
            return None
        info = self.actors[who]
        if act.tag == "LongitudinalAction":
            speed = child_at(act, "SpeedAction")
            if child_at(act, "SpeedProfileAction") is not None:
                return self.speed_profile(child_at(act, "SpeedProfileAction"), info)
            if child_at(act, "LongitudinalDistanceAction") is not None:
                return self.keep_gap(child_at(act, "LongitudinalDistanceAction"), who)
            relative = child_at(speed, "SpeedActionTarget", "RelativeTargetSpeed")
            if relative is not None:
                return self.relative_speed(speed.find("SpeedActionDynamics"), relative, info)
            target = child_at(speed, "SpeedActionTarget", "AbsoluteTargetSpeed")
            if speed is None or target is None:
                self.skip(first_of(only_child(act), act), f"<{first_of(only_child(act), act).tag}> is not translated",
                          "absolute and relative speed targets are translated")
                return None
            return self.speed_action(speed.find("SpeedActionDynamics"), target, info)
        if act.tag == "LateralAction":
            change = child_at(act, "LaneChangeAction")
            if change is None:
                self.skip(first_of(only_child(act), act), f"<{first_of(only_child(act), act).tag}> is not translated",
                          "the language has lane changes; lane offsets and lateral distances are not translated")
                return None
            return self.lane_change(change, who, info)
        if act.tag == "ActivateControllerAction":
            self.approx(act, "a controller: the entity follows its actions, as under the default controller "
                             "of OpenSCENARIO (the driver models of esmini are not emulated)")
            return None
        if act.tag == "ControllerAction":
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
        if act.tag == "TeleportAction":
            return self.teleport(act, who)
        if act.tag == "SynchronizeAction":
            return self.synchronize(act, who)
        if act.tag == "RoutingAction" and child_at(act, "FollowTrajectoryAction") is not None:
            return self.trajectory(child_at(act, "FollowTrajectoryAction"), who)
        self.skip(act, f"<{act.tag}> is not translated",
                  "translated: speed (absolute, relative, profiles), lane changes, longitudinal distance, "
                  "synchronize, polyline trajectories, routes in Init")
        return None
