"""Stop signs: where a map's stop signs hold traffic, and each actor's margin to running one.

A stop sign is an OpenDRIVE `<signal>` of a stop type (`STOP_SIGN_TYPES`). Its line is
where it stands on its road (its `s`), for traffic driving the way it faces, in the lanes
of its `<validity>`: the same lines as a light's (`lights.stop_lines`). An actor *stops*
for a line when its speed falls below `STOPPED_MS` while its front bumper is within
`STOP_ZONE_M` before the line (or up to `OVER_M` past it); it *runs* the sign when its
front crosses the line without having stopped for it (CARLA ScenarioRunner's
RunningStopTest: stopped means below 0.1 m/s near the sign). Whether it stopped is kept
per actor and line; nothing depends on set or hash order.

The twin's agents do not stop at signs (as OpenSCENARIO's default controller, their
scripts decide); the `bev` stack stops the ego at them (docs/stack.md), and the signal
`stop_sign(A)` with the oracle `no stop_sign` judges any actor.

Right of way: each sign kind (`SIGN_KINDS`: stop, yield, priority) sets the rule of the
approach it stands on (`junction_rule`); the `bev` stack reads it through its context
(`views.StackContext.junction_rule`). A sign's lines come from where it stands and from
each `<signalReference>` to it (`RoadNetwork.placements`: CARLA's towns place their signs
on the junctions' connecting roads so).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from addt_dsl.runtime.lights import REACH_M, PAST_M, StopLine, StopStation, signal_lines


@dataclass(frozen=True)
class SignKind:
    """A kind of traffic sign the map may have: its OpenDRIVE signal `types` (ASAM
    OpenDRIVE's catalogue, country "OpenDRIVE", follows Germany's StVO numbers; the US
    MUTCD's R codes), the OSI TrafficSign types that carry it to an external stack (the
    first is sent), and what it means for the ego's approach to the next junction."""

    name: str
    types: tuple[str, ...]
    osi_types: tuple[str, ...]
    means: str


# In order of precedence: an approach with signs of several kinds follows the first.
SIGN_KINDS: dict[str, SignKind] = {k.name: k for k in (
    SignKind("stop", ("206", "R1-1"), ("TYPE_STOP",),
             "stop at the line (below 0.05 m/s within 3 m of it), then judge the gaps as without a sign"),
    SignKind("yield", ("205", "R1-2"), ("TYPE_GIVE_WAY",),
             "give way: judge the gaps in crossing and oncoming traffic, no stop required; "
             "reach the junction at 20 km/h at most"),
    SignKind("priority", ("306", "301"), ("TYPE_RIGHT_OF_WAY_BEGIN", "TYPE_RIGHT_OF_WAY_NEXT_INTERSECTION"),
             "priority road (306) or priority at the next junction (301): crossing traffic that can still "
             "stop short of the ego's path braking at 2.5 m/s² (or as hard as it brakes) is not waited for; "
             "oncoming traffic and what is already in the junction are"),
)}
_KIND_OF_TYPE = {typ: k.name for k in SIGN_KINDS.values() for typ in k.types}
STOP_SIGN_TYPES = frozenset(SIGN_KINDS["stop"].types)
STOPPED_MS = 0.1  # [m/s] below this an actor has stopped (ScenarioRunner's SPEED_THRESHOLD)
STOP_ZONE_M = 4.0  # [m] how far before the line a stop counts (ScenarioRunner's PROXIMITY_THRESHOLD)
OVER_M = 0.5  # [m] a front this far over the line still stops for it
SIGN = ""  # the `controller` of a stop sign's `StopStation` (it has none)


def sign_kind(sig) -> str | None:
    """The `SIGN_KINDS` name of an OpenDRIVE signal (`road.Signal`), or None (a light, a
    sign of no listed kind)."""
    return None if sig.dynamic else _KIND_OF_TYPE.get(str(sig.type).strip())


def is_stop_sign(sig) -> bool:
    """Whether an OpenDRIVE signal (`road.Signal`) is a stop sign."""
    return sign_kind(sig) == "stop"


def sign_lines(network, kinds: Sequence[str] | None = None, controller: str | None = None) -> list[StopLine]:
    """The lines of every sign of `kinds` (default: all) on `network` (a `RoadNetwork`),
    where it stands and where references place it, in road and signal order; each line's
    `controller` is `controller` if given, else its kind's name."""
    out = []
    for road_id, sig in network.placements():
        kind = sign_kind(sig)
        if kind is not None and (kinds is None or kind in kinds):
            out.extend(signal_lines(network.road(road_id), road_id, sig, kind if controller is None else controller))
    return out


def stop_sign_lines(network) -> list[StopLine]:
    """The lines of every stop sign on `network` (a `RoadNetwork`), in road and signal order."""
    return sign_lines(network, ("stop",), SIGN)


def junction_rule(stations: Sequence[StopStation], junctions, front_u: float) -> str | None:
    """The rule (a `SIGN_KINDS` name) of the approach to the next junction the front (path
    station `front_u` [m]) has not left, or None (no sign: give way). `stations`: the
    signs' lines on the path, each `controller` its kind; `junctions`: (entry, exit, ...)
    stations in path order. A sign governs the junction when its line lies after the
    previous junction's exit, at most at this one's exit and at most `REACH_M` before its
    entry (a reference places it on the connecting road, inside the junction)."""
    lo = -float("inf")
    for entry, exit_, *_ in junctions:
        if exit_ > front_u:
            kinds = {st.controller for st in stations if lo < st.u <= exit_ and st.u >= entry - REACH_M}
            return next((k for k in SIGN_KINDS if k in kinds), None)
        lo = exit_
    return None


def next_sign(lines_u: Sequence[float], front_u: float, stopped: Sequence[float] = ()) -> float | None:
    """Station [m] of the first stop-sign line (`lines_u`, path stations in path order) at or
    ahead of `front_u - OVER_M` and within `REACH_M`, other than those in `stopped` (lines
    already stopped for), or None."""
    for u in lines_u:
        if u < front_u - OVER_M or u in stopped:
            continue
        return u if u - front_u <= REACH_M else None
    return None


class SignsRuntime:
    """Which stop-sign lines each actor has stopped for, and its margin to running one."""

    def __init__(self):
        self._stopped: dict[tuple[str, float], bool] = {}  # (actor, line) -> stopped for it
        self._behind: dict[tuple[str, float], bool] = {}  # (actor, line) -> was behind it

    def margin(self, actor: str, front_u: float, speed: float, stations: Sequence[StopStation]) -> float:
        """The actor's margin to running a stop sign [m] (signal `stop_sign`): the distance
        of its front to the nearest line ahead it has not stopped for (`REACH_M` at most),
        negative once it crossed a line it was behind without stopping (until `PAST_M`
        past it). Updates whether it stopped: call once per sample, in time order."""
        margin = REACH_M
        for st in stations:
            key = (actor, st.u)
            d = st.u - front_u
            if -OVER_M <= d <= STOP_ZONE_M and abs(speed) < STOPPED_MS:
                self._stopped[key] = True
            if d >= 0.0:
                self._behind[key] = True
                if not self._stopped.get(key):
                    margin = min(margin, d)
            elif self._behind.get(key) and not self._stopped.get(key) and d > -PAST_M:
                margin = min(margin, d)
        return margin


def markdown_table() -> str:
    """The sign kinds as a Markdown table (docs/language.md)."""
    rows = ["| kind | OpenDRIVE `type` | OSI TrafficSign | the ego's approach (`bev`) |", "|---|---|---|---|"]
    for k in SIGN_KINDS.values():
        rows.append(f"| `{k.name}` | {', '.join(f'`{t}`' for t in k.types)} | "
                    f"{', '.join(f'`{t}`' for t in k.osi_types)} | {k.means} |")
    return "\n".join(rows)


if __name__ == "__main__":
    print(markdown_table())
