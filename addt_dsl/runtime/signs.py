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

Right of way: each sign kind (`SIGN_KINDS`) says which rule it gives the approach it stands
on (stop, yield, priority or none) and whether it begins or ends a priority road;
`junction_rule` walks the ego's junctions with them (a priority road, StVO 306, keeps its
priority at every junction until sign 307 or an approach with a yield or stop sign ends
it; 301 gives priority at the next junction only). The `bev` stack reads the rule through
its context (`views.StackContext.junction_rule`). A sign's lines come from where it stands
and from each `<signalReference>` to it (`RoadNetwork.placements`: CARLA's towns place their
signs on the junctions' connecting roads so).
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
    first is sent), the rule it gives the approach to the junction it stands before
    (`RULES`; None: none), whether it begins (True) or ends (False) a priority road (None:
    neither), and what it means for the ego."""

    name: str
    types: tuple[str, ...]
    osi_types: tuple[str, ...]
    rule: str | None
    road: bool | None
    means: str


RULES = ("stop", "yield", "priority")  # in order of precedence on one approach

# In order of precedence (ties at one station are taken in this order too).
SIGN_KINDS: dict[str, SignKind] = {k.name: k for k in (
    SignKind("stop", ("206", "R1-1"), ("TYPE_STOP",), "stop", False,
             "stop at the line (below 0.05 m/s within 3 m of it), then judge the gaps as without a sign; "
             "ends a priority road"),
    SignKind("yield", ("205", "R1-2"), ("TYPE_GIVE_WAY",), "yield", False,
             "give way: judge the gaps in crossing and oncoming traffic, no stop required; "
             "reach the junction at 20 km/h at most; ends a priority road"),
    SignKind("priority", ("301",), ("TYPE_RIGHT_OF_WAY_NEXT_INTERSECTION",), "priority", None,
             "priority at the next junction: crossing traffic that can still stop short of the ego's path "
             "braking at 2.5 m/s² (or as hard as it brakes) is not waited for; oncoming traffic and what is "
             "already in the junction are"),
    SignKind("priority_road", ("306",), ("TYPE_RIGHT_OF_WAY_BEGIN",), "priority", True,
             "priority road: priority as behind `priority` at this junction and at every one after it, "
             "until a `priority_road_end` sign or an approach with a stop or yield sign"),
    SignKind("priority_road_end", ("307",), ("TYPE_RIGHT_OF_WAY_END",), None, False,
             "end of the priority road: the junctions after it follow their own signs"),
)}
_ORDER = {name: i for i, name in enumerate(SIGN_KINDS)}
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
    """The rule (one of `RULES`) of the approach to the next junction the front (path
    station `front_u` [m]) has not left, or None (no sign: give way). `stations`: the
    signs' lines on the path, each `controller` its kind; `junctions`: (entry, exit, ...)
    stations in path order. A sign's rule governs the junction when its line lies after the
    previous junction's exit, at most at this one's exit and at most `REACH_M` before its
    entry (a reference places it on the connecting road, inside the junction); the most
    precedent rule wins. An approach without a rule has priority while the ego is on a
    priority road: the signs' lines up to each junction's exit, taken in station order,
    begin and end it (`SignKind.road`)."""
    signs = sorted(stations, key=lambda st: (st.u, _ORDER[st.controller]))
    on_road, k = False, 0
    for entry, exit_, *_ in junctions:
        rules = set()
        while k < len(signs) and signs[k].u <= exit_:
            kind = SIGN_KINDS[signs[k].controller]
            if kind.rule is not None and signs[k].u >= entry - REACH_M:
                rules.add(kind.rule)
            if kind.road is not None:
                on_road = kind.road
            k += 1
        if exit_ > front_u:
            return next((r for r in RULES if r in rules), "priority" if on_road else None)
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
    rows = ["| kind | OpenDRIVE `type` | OSI TrafficSign | approach rule | the ego's approach (`bev`) |",
            "|---|---|---|---|---|"]
    for k in SIGN_KINDS.values():
        rows.append(f"| `{k.name}` | {', '.join(f'`{t}`' for t in k.types)} | "
                    f"{', '.join(f'`{t}`' for t in k.osi_types)} | {f'`{k.rule}`' if k.rule else 'none'} | "
                    f"{k.means} |")
    return "\n".join(rows)


if __name__ == "__main__":
    print(markdown_table())
