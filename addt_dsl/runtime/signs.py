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
"""

from __future__ import annotations

from collections.abc import Sequence

from addt_dsl.runtime.lights import REACH_M, PAST_M, StopLine, StopStation

# Signal types of a stop sign: ASAM OpenDRIVE's catalogue (country "OpenDRIVE") and
# Germany's StVO use 206, the US MUTCD R1-1.
STOP_SIGN_TYPES = frozenset({"206", "R1-1"})
STOPPED_MS = 0.1  # [m/s] below this an actor has stopped (ScenarioRunner's SPEED_THRESHOLD)
STOP_ZONE_M = 4.0  # [m] how far before the line a stop counts (ScenarioRunner's PROXIMITY_THRESHOLD)
OVER_M = 0.5  # [m] a front this far over the line still stops for it
SIGN = ""  # the `controller` of a stop sign's `StopStation` (it has none)


def is_stop_sign(sig) -> bool:
    """Whether an OpenDRIVE signal (`road.Signal`) is a stop sign."""
    return not sig.dynamic and str(sig.type).strip() in STOP_SIGN_TYPES


def stop_sign_lines(network) -> list[StopLine]:
    """The lines of every stop sign on `network` (a `RoadNetwork`), in road and signal order."""
    out = []
    for road_id in sorted(network.roads, key=_natural):
        road = network.roads[road_id]
        for sig in road.signals:
            if not is_stop_sign(sig):
                continue
            directions = {"+": (1,), "-": (-1,)}.get(sig.orientation, (1, -1))
            driving = road.driving_lane_ids(sig.s)
            for direction in directions:
                lanes = [i for i in driving if road.travel_direction(i) == direction]
                if sig.validity is not None:
                    lanes = [i for i in lanes if sig.validity[0] <= i <= sig.validity[1]]
                if lanes:
                    out.append(StopLine(SIGN, sig.id, road_id, sig.s, direction, tuple(lanes)))
    return out


def _natural(road_id: str):
    return (0, int(road_id), "") if road_id.lstrip("-").isdigit() else (1, 0, road_id)


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
