"""Private actions: an action element dispatched to its registered translation (registry.ACTIONS;
the translations are in the actions_* modules); global actions are the storyboard's
(`storyboard.Storyboard.event`, `init`)."""

from addt_dsl import units
from addt_dsl.interop.openscenario.registry import ACTIONS
from addt_dsl.interop.openscenario.xml import child_at, first_of, only_child

# What an action that is not translated names as translated (the diagnostic's note).
TRANSLATED = ("translated: speed (absolute, relative, profiles), lane changes, lane offsets, "
              "longitudinal distance, "
              "synchronize, polyline trajectories, routes in Init")
# An action that wraps one of several (LongitudinalAction: a SpeedAction, ...): the inner
# elements tried in this order, and the note of a refused inner element (None: the wrapper
# itself is refused, with TRANSLATED).
WRAPPERS = {
    "LongitudinalAction": (("SpeedProfileAction", "LongitudinalDistanceAction", "SpeedAction"),
                           "absolute and relative speed targets are translated"),
    "LateralAction": (("LaneChangeAction", "LaneOffsetAction"),
                      "the language has lane changes and lane offsets; lateral distances are not translated"),
    "RoutingAction": (("FollowTrajectoryAction",), None),
}

for _name, _status, _note in (
        ("LateralDistanceAction", "refused", "the language has no behaviour that keeps a lateral distance"),
        ("AssignRouteAction", "approx", "in Init only (the actor's route); in an event it is refused: the "
                                        "language has no route change during a run"),
        ("AcquirePositionAction", "refused", "the language has no behaviour that drives to a position"),
        ("RandomRouteAction", "refused", "the language has no random routes"),
        ("VisibilityAction", "refused", "the twin has no sensor visibility of an entity; an exported group's "
                                        "no-op anchor only"),
        ("AppearanceAction", "refused", "the twin has no vehicle light states or animations"),
        ("TrailerAction", "refused", "the twin has no trailers"),
        ("OverrideControllerValueAction", "approx", "inside a ControllerAction: ignored with W0802 (the twin has "
                                                    "no pedal, steering or gear overrides)"),
        ("AssignControllerAction", "approx", "inside a ControllerAction: a controller named addt_<behaviour> "
                                             "(addtc export) is that behaviour; others W0802, the entity follows "
                                             "its actions"),
):
    ACTIONS.declare(_name, _status, _note)


class Actions:
    def private_action(self, act, who: str):
        """The behaviour clause an action starts, or None after a diagnostic."""
        if who == "ego" and not self.scripted_ego:
            # The speeds the file asks of its ego: the stack's cruise speed where it starts standing.
            target = child_at(act, "SpeedAction", "SpeedActionTarget", "AbsoluteTargetSpeed")
            profile = act.find("SpeedProfileAction")
            for el, attr in ([(target, "value")] if target is not None else []) + \
                    [(e, "speed") for e in (profile.iterfind("SpeedProfileEntry") if profile is not None else ())]:
                self.actors[who].setdefault("speed_targets", []).append((self.number(el, attr, units.SPEED), el))
            self.approx(act, f"<{act.tag}> on the ego: the stack under test drives the ego",
                        "`addtc import --ego scripted` makes the ego follow the file's actions")
            return None
        if act.tag == "LongitudinalAction" and (walk := self.carla_walk(act, who)) is not None:
            return walk  # ScenarioRunner moves it along its heading
        if act.tag in WRAPPERS:
            names, note = WRAPPERS[act.tag]
            for name in names:
                inner = act.find(name)
                if inner is not None and ACTIONS.translator(name) is not None:
                    return ACTIONS.translator(name)(self, inner, who, act)
            if note is not None:
                return self.refuse_inner(act, note)
        elif ACTIONS.translator(act.tag) is not None:
            return ACTIONS.translator(act.tag)(self, act, who, act)
        self.skip(act, f"<{act.tag}> is not translated", TRANSLATED)
        return None

    def refuse_inner(self, act, note: str) -> None:
        """An action of a wrapper (or the wrapper) that is not translated: refused, with `note`."""
        inner = first_of(only_child(act), act)
        self.skip(inner, f"<{inner.tag}> is not translated", note)
        return None
