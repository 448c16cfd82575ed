"""The trace of one run: signals on a fixed clock, events, per-node latencies.

Arrays are numpy, sampled every `period_s` (the physics step). `digest()` hashes every
array bit for bit: the determinism tests compare digests.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import numpy as np

ACTOR_FIELDS = ("x", "y", "heading", "speed", "accel", "yaw_rate", "s", "t", "lane_offset",
                "steer", "clearance")


@dataclass
class ActorTrack:
    """Per-actor signals, one value per clock sample. Units: m, rad, m/s, m/s^2, rad/s."""

    name: str
    length_m: float
    width_m: float
    x: np.ndarray
    y: np.ndarray
    heading: np.ndarray
    speed: np.ndarray
    accel: np.ndarray
    yaw_rate: np.ndarray
    s: np.ndarray  # station along its road [m] (on a route: along the route, in driving direction)
    # lateral offset from the road reference line, left positive [m] (route: from the route
    # lane's centre, driver's left positive)
    t: np.ndarray
    lane_offset: np.ndarray  # offset from the centre of the lane it started in / targets [m]
    steer: np.ndarray  # front wheel angle [rad]
    clearance: np.ndarray  # distance to the nearest other actor's box, negative = overlap [m]
    # The station frame `s` and `t` are measured in: the road id, or the route's key for an
    # actor on a route or driving against s. Actors in one frame compare stations (gap, ttc).
    frame: str = ""


@dataclass
class Event:
    time_s: float
    # collision | fault | fault_window | stack_error | trigger | goal | watchdog | left_road | behavior | variable
    kind: str
    detail: dict = field(default_factory=dict)


SERIES_COLUMNS = ("times", "value", "before")  # the parallel lists of a series fault event


def injection_count(event: Event) -> int:
    """Injections one `fault` event stands for: 1, or the length of a series event."""
    times = event.detail.get("times")
    return 1 if times is None else len(times)


@dataclass
class Trace:
    period_s: float
    time: np.ndarray
    actors: dict[str, ActorTrack]
    # Latency per node [s], sample-and-hold on the clock; "e2e" is sensor stamp to actuation.
    latency: dict[str, np.ndarray]
    events: list[Event] = field(default_factory=list)
    # Values published by stack nodes (for masked vs silent-corruption classification).
    outputs: dict[str, np.ndarray] = field(default_factory=dict)
    object_count: np.ndarray | None = None
    status: str = "ok"  # ok | detected (exception / NaN / watchdog)
    error: str = ""
    # State of each named step (`lead.brake_hard`) per sample: 0 waiting, 1 started,
    # 2 ended (runtime/signals.py STEP_*).
    steps: dict[str, np.ndarray] = field(default_factory=dict)
    # Traffic lights: each controller's state code per sample (plan.LIGHT_STATES), and each
    # actor's margin to running a red light [m] (signals `light`, `red_light`); empty
    # without lights.
    lights: dict[str, np.ndarray] = field(default_factory=dict)
    red_margin: dict[str, np.ndarray] = field(default_factory=dict)
    # Each actor's margin to running a stop sign [m] (signal `stop_sign`); empty without
    # stop signs on the maps.
    stop_margin: dict[str, np.ndarray] = field(default_factory=dict)
    # Each actor's lane id per sample (signal `lane_id`), in runs whose formulas read it.
    lanes: dict[str, np.ndarray] = field(default_factory=dict)
    # Each actor's distance to its road's outer edge [m] (signal `road_edge`), for the actors
    # the scenario reads it of.
    road_edge: dict[str, np.ndarray] = field(default_factory=dict)
    # Each actor's distance left to the end of its road or route [m] (signal `road_end`), for
    # the actors the scenario reads it of.
    road_end: dict[str, np.ndarray] = field(default_factory=dict)
    # Scenario variables' values per sample (signal `var`); empty without variables.
    variables: dict[str, np.ndarray] = field(default_factory=dict)
    # Each actor's `wrong_way` and `off_lanes` state per sample (+1 holds, -1 not), for the
    # actors the scenario reads them of.
    wrong_way: dict[str, np.ndarray] = field(default_factory=dict)
    off_lanes: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def duration_s(self) -> float:
        return float(self.time[-1]) if len(self.time) else 0.0

    def events_of(self, kind: str) -> list[Event]:
        return [e for e in self.events if e.kind == kind]

    def fault_injections(self) -> list[dict]:
        """One row per fault injection, in event order: `time_s` plus the event's fields.
        A series event (one per location of a high-rate fault such as `random_value`, its
        `times`/`value`/`before` parallel lists) expands into one row per entry."""
        rows = []
        for e in self.events:
            if e.kind != "fault":
                continue
            d = e.detail
            if "times" not in d:
                rows.append({"time_s": e.time_s, **d})
                continue
            fixed = {k: v for k, v in d.items() if k not in SERIES_COLUMNS}
            rows.extend({"time_s": t, **fixed, "value": v, "before": b}
                        for t, v, b in zip(d["times"], d["value"], d["before"]))
        return rows

    def injection_count(self) -> int:
        """How many injections the `fault` events record (a series event counts each entry)."""
        return sum(injection_count(e) for e in self.events if e.kind == "fault")

    def digest(self) -> str:
        h = hashlib.sha256()
        h.update(np.ascontiguousarray(self.time).tobytes())
        for name in sorted(self.actors):
            track = self.actors[name]
            for f in ACTOR_FIELDS:
                h.update(np.ascontiguousarray(getattr(track, f)).tobytes())
        for name in sorted(self.latency):
            h.update(name.encode())
            h.update(np.ascontiguousarray(self.latency[name]).tobytes())
        for name in sorted(self.outputs):
            h.update(name.encode())
            h.update(np.ascontiguousarray(self.outputs[name]).tobytes())
        for e in self.events:
            d = e.detail
            if e.kind == "fault" and "times" in d:
                # A series event: its columns hashed as float64 bytes (exact, and a repr of
                # thousands of floats would cost more than the injections themselves).
                h.update(repr((e.time_s, e.kind, sorted((k, v) for k, v in d.items()
                                                         if k not in SERIES_COLUMNS))).encode())
                for column in SERIES_COLUMNS:
                    h.update(column.encode())
                    h.update(np.asarray(d[column], dtype=np.float64).tobytes())
                continue
            h.update(repr((e.time_s, e.kind, sorted(d.items()))).encode())
        for name in sorted(self.steps):  # none without named steps: earlier digests hold
            h.update(name.encode())
            h.update(np.ascontiguousarray(self.steps[name], dtype=np.int8).tobytes())
        h.update(self.status.encode())
        if self.object_count is not None:  # what the stack perceived: a replay must see the same
            h.update(b"objects:")
            h.update(np.ascontiguousarray(self.object_count, dtype=np.float64).tobytes())
        # (The step is in `time`; an error's text is in its `stack_error` event or fixed by
        # `status`.) Only scenarios with lights hash them: digests of the others stay what they were.
        for label, table in (("light:", self.lights), ("red_margin:", self.red_margin),
                             ("stop_margin:", self.stop_margin), ("lane_id:", self.lanes),
                             ("road_edge:", self.road_edge), ("road_end:", self.road_end),
                             ("var:", self.variables), ("wrong_way:", self.wrong_way),
                             ("off_lanes:", self.off_lanes)):
            for name in sorted(table):
                h.update((label + name).encode())
                h.update(np.ascontiguousarray(table[name]).tobytes())
        return h.hexdigest()
