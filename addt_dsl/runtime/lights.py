"""Traffic lights: phase programs as pure functions of time, and where each light's stop line is.

A controller's state is a function of the plan and the time only (as in HighwayEnv): its
program cycles green -> yellow -> red, green starting at `offset_s` (and every cycle
before and after it); state changes fired by steps (`at 5 s light west state red`) are a
list of `(time_s, state)` the runtime appends to, and the latest one at or before `t`
wins (`program` hands the light back to its cycle). `state_at` takes arrays of times.

States are numbers in traces and formulas (`light(west) == red`): `STATE_CODES`.

A stop line is where a signal stands on its road (its `s`), for traffic driving the way
the signal faces (`orientation` "+": along s, "-": against, "none": both) in the lanes of
its `<validity>` (all lanes of that direction without one). Only signals that govern
vehicles make stop lines (`SIGNAL_KINDS`): a pedestrian light governs the crossing.

Several lights on one stop line (one station, different controllers) hold traffic by the
most restrictive state among them (`next_stop`); nothing depends on the order they were
found in (set or hash order), so every process gives the same run.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from addt_dsl.plan import LIGHT_PROGRAM, LIGHT_STATES

STATE_CODES = LIGHT_STATES
GREEN, YELLOW, RED = STATE_CODES["green"], STATE_CODES["yellow"], STATE_CODES["red"]
PROGRAM = LIGHT_PROGRAM  # a state change that hands the light back to its program


@dataclass(frozen=True)
class Program:
    """One green/yellow/red cycle [s]; green starts at `offset_s` (mod the cycle)."""

    green_s: float
    yellow_s: float
    red_s: float
    offset_s: float = 0.0

    @property
    def cycle_s(self) -> float:
        return self.green_s + self.yellow_s + self.red_s

    def state(self, t):
        """State code at time(s) `t` [s] (scalar -> float, array -> array)."""
        tt = np.asarray(t, dtype=float)
        cycle = self.cycle_s
        if cycle <= 0.0:
            out = np.full(tt.shape, GREEN)
        else:
            phase = np.mod(tt - self.offset_s, cycle)
            out = np.where(phase < self.green_s, GREEN, np.where(phase < self.green_s + self.yellow_s, YELLOW, RED))
        return float(out) if out.ndim == 0 else out


def state_at(program: Program, changes: Sequence[tuple[float, str]], t):
    """State code at time(s) `t` [s]: the latest change at or before `t` (its state, or the
    program's after `program`), else the program. `changes` are in time order."""
    tt = np.asarray(t, dtype=float)
    out = np.asarray(program.state(tt), dtype=float).copy()
    for i, (time_s, state) in enumerate(changes):
        end = changes[i + 1][0] if i + 1 < len(changes) else np.inf
        if state == PROGRAM:
            continue
        mask = (tt >= time_s - 1e-9) & (tt < end - 1e-9)
        out = np.where(mask, STATE_CODES[state], out)
    return float(out) if out.ndim == 0 else out


# What an OpenDRIVE signal `type` (country "OpenDRIVE", ASAM OpenDRIVE's signal catalogue)
# governs: "vehicle" signals make stop lines, "pedestrian" ones do not (they still belong to
# their controller, whose state `light(NAME)` records). A type not listed, and a signal
# declared in the language, is a vehicle light.
SIGNAL_KINDS = {
    "1000001": "vehicle",  # traffic light: red, yellow, green
    "1000002": "pedestrian",  # pedestrian light: red, green
    "1000009": "vehicle",  # two-lamp traffic light (red/yellow, yellow/green)
    "1000011": "vehicle",  # traffic light with arrows
}


def governs_vehicles(sig_type: str) -> bool:
    """Whether a signal of OpenDRIVE `type` holds vehicles at its stop line (`SIGNAL_KINDS`)."""
    return SIGNAL_KINDS.get(str(sig_type).strip(), "vehicle") == "vehicle"


@dataclass(frozen=True)
class StopLine:
    """Where traffic governed by a controller stops: road station `s` [m] of `road_id`, for
    traffic driving in `direction` (+1 along s, -1 against) in `lanes` (map lane ids;
    empty: every lane of that direction)."""

    controller: str
    signal: str
    road_id: str
    s: float
    direction: int
    lanes: tuple[int, ...] = ()

    def governs(self, road_id: str, direction: int, lane: int) -> bool:
        return (road_id == self.road_id and direction == self.direction
                and (not self.lanes or lane in self.lanes))


def stop_lines(network, controller: str, signal_ids: Iterable[str], inline: dict | None = None) -> list[StopLine]:
    """The stop lines of a controller's signals on `network` (a `RoadNetwork`); `inline`
    maps names of signals declared in the language to `(road_id, s, lanes)`."""
    out = []
    for sid in signal_ids:
        if inline and sid in inline:
            road_id, s, lanes = inline[sid]
            road = network.road(road_id)
            lanes = tuple(lanes) or tuple(i for i in road.driving_lane_ids(s) if road.travel_direction(i) > 0)
            for direction in sorted({road.travel_direction(i) for i in lanes}, reverse=True):
                out.append(StopLine(controller, sid, road_id, s, direction,
                                    tuple(i for i in lanes if road.travel_direction(i) == direction)))
            continue
        for road_id, sig in network.placements(sid):  # where it stands, and its references
            if not governs_vehicles(sig.type):
                continue  # a pedestrian light: its stop line is the crossing's, not the road's
            out.extend(signal_lines(network.road(road_id), road_id, sig, controller))
    return out


def signal_lines(road, road_id: str, sig, controller: str) -> list[StopLine]:
    """The stop lines a map's signal (`road.Signal`) makes on its road: one per direction it
    faces with a driving lane of its `<validity>` there.

    A placement by a `<signalReference>` whose validity names driving lanes holds those
    lanes each in its own direction of travel, whatever its orientation: as CARLA reads
    them (`Signal::IsLaneValid`, validity only); its towns write a reference's orientation
    as the way the sign's face points, opposite to the standard's (on every reference of
    Town01, Town07 and Town10HD)."""
    out = []
    driving = road.driving_lane_ids(sig.s)
    directions = {"+": (1,), "-": (-1,)}.get(sig.orientation, (1, -1))
    if sig.reference and sig.validity is not None:
        directions = (1, -1)
    for direction in directions:
        lanes = [i for i in driving if road.travel_direction(i) == direction]
        if sig.validity is not None:
            lanes = [i for i in lanes if sig.validity[0] <= i <= sig.validity[1]]
        if lanes:
            out.append(StopLine(controller, sig.id, road_id, sig.s, direction, tuple(lanes)))
    return out


@dataclass(frozen=True)
class StopStation:
    """A stop line on one actor's road or path: path station `u` [m] of the line, held by
    `controller` (several controllers on one line: one station each)."""

    u: float
    controller: str


def stations_on(lines: Sequence[StopLine], legs, station) -> list[StopStation]:
    """The stop lines an actor meets along its legs (`route.Leg`-like: road_id, direction,
    s_from, s_to, lane), as stations of its path (`station(road_id, s)`), in path order."""
    out = []
    for leg in legs:
        lo, hi = sorted((leg.s_from, leg.s_to))
        for line in lines:
            if line.governs(leg.road_id, leg.direction, leg.lane) and lo - 1e-6 <= line.s <= hi + 1e-6:
                out.append(StopStation(float(station(leg.road_id, line.s)), line.controller))
    # Sorted by station, then controller: the order never depends on set or hash order.
    return sorted(set(out), key=lambda st: (st.u, st.controller))


SAME_LINE_M = 1e-6  # [m] stations closer than this are one stop line


def next_stop(stations: Sequence[StopStation], front_u: float, state_of) -> tuple[float, float] | None:
    """(station [m], state code) of the first stop line at or ahead of `front_u - 0.5` [m]
    among `stations` (in path order), or None; where several controllers hold one line,
    its state is the most restrictive of theirs (red over yellow over green).
    `state_of(controller)` gives a controller's state code now."""
    found = None
    for st in stations:
        if st.u < front_u - 0.5:
            continue
        if found is None:
            found = (st.u, state_of(st.controller))
        elif st.u - found[0] <= SAME_LINE_M:
            found = (found[0], max(found[1], state_of(st.controller)))
        else:
            break
    return found


COMFORT_DECEL = 2.5  # [m/s^2] an agent stops for a red light braking at most this hard
YELLOW_DECEL = 3.0  # [m/s^2] an agent stops at yellow only if it can stop braking at most this hard
STOP_GAP_M = 1.0  # [m] the front bumper stops this far before the line
REACH_M = 100.0  # [m] stop lines further ahead are not considered; the red-light margin's cap
PAST_M = 30.0  # [m] how far past a line crossed at red the margin stays negative


def stop_accel(speed: float, dist_m: float, state: float) -> float | None:
    """Acceleration [m/s^2] that stops an agent `STOP_GAP_M` before a line `dist_m` ahead of
    its front, for a light in `state`; None when the light does not hold it (green, or a
    yellow it cannot stop for comfortably)."""
    if state == GREEN or dist_m < -0.5 or dist_m > REACH_M:
        return None
    room = dist_m - STOP_GAP_M
    if state == YELLOW and speed * speed > 2.0 * YELLOW_DECEL * max(dist_m, 1e-6):
        return None  # too close to stop: go on through the yellow
    if room <= 0.5:
        return max(-8.0, -speed / 0.2)  # at the line: stop and hold
    needed = speed * speed / (2.0 * room)  # constant deceleration that stops at the line
    return max(-8.0, -needed) if needed >= COMFORT_DECEL else None


class LightsRuntime:
    """Every controller's state during a run: its program and the changes fired so far."""

    def __init__(self, programs: dict[str, Program]):
        self.programs = programs
        self.changes: dict[str, list[tuple[float, str]]] = {name: [] for name in programs}
        self._armed: dict[tuple[str, float], bool] = {}

    def change(self, name: str, time_s: float, state: str) -> None:
        self.changes[name].append((time_s, state))

    def state(self, name: str, time_s: float) -> float:
        return state_at(self.programs[name], self.changes[name], time_s)

    def red_margin(self, actor: str, front_u: float, stations: Sequence[StopStation], time_s: float) -> float:
        """The actor's margin to running a red light [m] (signal `red_light`): the distance to
        the nearest stop line it approaches at red, negative once it crossed one it was
        behind when (or while) the light was red; `REACH_M` when none."""
        margin = REACH_M
        for st in stations:
            key = (actor, st.u, st.controller)
            if self.state(st.controller, time_s) != RED:
                self._armed[key] = False
                continue
            d = st.u - front_u
            if d >= 0.0:
                self._armed[key] = True
                margin = min(margin, d)
            elif self._armed.get(key) and d > -PAST_M:
                margin = min(margin, d)
        return margin
