"""What the twin offers the code it hosts: the declared interfaces.

Behaviours, sensors, perception, stacks and faults see the world (faults: the sensor,
frame and stack they act on) only through these Protocols; none reaches into the run's
state (`state.RunState`). The twin implements them (`state.RunState` the world views,
`state.Context` the stack's context); a remote stack's server implements `StackContext`
from what the bridge protocol sends (`stack.bridge_server.RemoteContext`).
`tests/unit/runtime/test_views.py` checks that each consumer uses only the members
declared here.

Units: positions and stations [m], headings [rad], speeds [m/s], times [s].
"""

from __future__ import annotations

from typing import Iterator, Protocol

import numpy as np


class AgentView(Protocol):
    """One agent as a behaviour reads and moves it (its `start`, `accel`, `ended` get it as
    `agent`): `agent_arrays.AgentState`, a view of its slot in the batch's agent arrays for the
    numbers the loop moves, its own for the rest. Stations and offsets [m], speeds [m/s]."""

    name: str
    road: str  # the road (or path) it is on
    length_m: float
    width_m: float
    s: float  # station [m]
    t: float  # lateral offset from the reference line [m]
    speed: float  # along its own path [m/s]
    accel: float  # of the last step [m/s^2]
    ground_scale: float  # ground per metre of station at its offset [m/m]
    placed: bool  # teleported this step: it stays put until the next
    moved: bool  # has had a speed above 0 (its declared yaw no longer holds)
    lane: int
    # the lateral manoeuvre: offsets [m], times [s], the blend, whether the station keeps its progress
    t_target: float
    t_start: float
    lc_start_s: float
    lc_duration_s: float
    lc_shape: str
    lc_keeps_station: bool
    lc_centre: tuple | None  # a change onto a moving lane centre: its samples
    heading_rel: float  # a walker's direction relative to its road [rad]
    lane_anchor: tuple | None  # after a change into a lane that moves: kept on that lane


class BehaviorWorld(Protocol):
    """What a behaviour may read (its `start`, `accel`, `ended` get it as `world`)."""

    dt: float  # the physics step [s]

    def leader_of(self, agent) -> tuple[float, float] | None:
        """(bumper gap [m], speed [m/s]) of the nearest actor ahead in the agent's lane."""

    def actor_station(self, name: str) -> tuple[float, float, float] | None:
        """(s [m], speed [m/s], length [m]) of an actor on its own road or path."""

    def actor_lane(self, name: str) -> int | None:
        """The lane an actor is in now (None off the lanes)."""

    def occupants(self, road_id: str) -> Iterator:
        """Every actor on a road (`neighbours.Member`: name, road, s, t, speed, length_m)."""

    def road_coords(self, agent, x: float, y: float) -> tuple[float, float]:
        """(s, t) of a world point on an agent's road or path."""

    def from_road_coords(self, agent, s: float, t: float) -> tuple[float, float]:
        """An agent's (s, t) of OpenDRIVE road coordinates on the road it is on now."""

    def lane_t(self, road_id: str, lane: int, s: float) -> float:
        """Offset [m] of a lane's centre at station `s`."""

    def lane_moves(self, road_id: str, lane: int) -> bool:
        """Whether a lane's centre offset varies along the road (a lane beside it narrows, a
        route's reference crosses over): an agent changing into it then follows it."""

    def road_band_t(self, road_id: str, s: float) -> tuple[float, float]:
        """(right, left) offsets [m] of the drivable band at station `s`."""

    def live_value(self, expr) -> float:
        """A live setting (`speed(ego) + 5 km/h`) on the state recorded this step."""


class SensorWorld(Protocol):
    """What a sensor's `capture(world, time_s)` may read."""

    def ego_pose(self) -> tuple[float, float, float, float]:
        """(x, y, heading, speed) of the ego."""

    def ego_frame(self) -> tuple[float, float, float, float, float]:
        """(x, y, z of the road under the ego, heading, pitch nose-up) for sensor mounts."""

    def ego_state(self):
        """The ego's `vehicle.VehicleState` (read only)."""

    def rng(self, name: str) -> np.random.Generator:
        """The named generator of the world (seeded by the RunSpec)."""

    def ray_cast(self, starts: np.ndarray, ends: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(body id or -1, hit fraction) of each ray, the ego's body ignored. A lidar's
        `starts` are its one origin, every row a read-only view of it (stride 0)."""

    def ray_scene(self) -> tuple | None:
        """What `ray_cast` casts against where the world is boxes and a ground plane (the ego's
        box ignored): `PhysicsWorld.ray_scene`'s tuple, for a sensor that casts in its own
        kernel with the same bits; None where rays must go through `ray_cast`. Optional: a
        world without it answers rays through `ray_cast` alone."""

    def render(self, width: int, height: int, view, projection, segmentation: bool = True):
        """(rgb, z-buffer, body ids) of a pinhole view."""


class StackContext(Protocol):
    """What an in-process stack (`stack.bev`) may read and do."""

    now: float  # the stack's clock [s]
    faults: object  # the fault schedule (`runtime.faults.FaultSchedule`): the stack's hooks ask it
    wheelbase_m: float
    ego_length_m: float
    ego_width_m: float
    ego_mass_kg: float
    ego_mu: float
    ego_lane: int  # the ego's lane id in driving convention

    def rng(self, name: str) -> np.random.Generator:
        """The stack's named generator (seeded by the RunSpec)."""

    def ego_pose(self) -> tuple[float, float, float, float]:
        """(x, y, heading, speed) of the ego."""

    def ego_station(self) -> float:
        """The ego's station [m] on its road or route: a hint to project near."""

    def ego_road(self):
        """(the ego's road or route as a path, its id)."""

    def sensor(self, name: str):
        """A sensor's object (its nominal and actual mounts, its period)."""

    def junction_ahead(self, s: float):
        """(entry station, x, y of its middle, exit station) of the next junction, or None."""

    def stop_line_ahead(self, s: float):
        """(station, state code) of the next traffic light's stop line ahead, or None."""

    def stop_sign_ahead(self, s: float, stopped: tuple[float, ...] = ()) -> float | None:
        """Station of the next stop sign's line ahead but those in `stopped`, or None."""

    def junction_rule(self, s: float) -> str | None:
        """The map's signs' rule for the approach to the next junction (`runtime.signs.RULES`:
        "stop", "yield", "priority"), or None (no sign, no priority road)."""

    def event(self, kind: str, **detail) -> None:
        """Record an event now."""

    def emit(self, event) -> None:
        """Record an event stamped by its source (`trace.Event`)."""

    def apply_command_at(self, time_s: float, steer: float, accel: float) -> None:
        """A command [rad, m/s^2] that becomes effective at `time_s`."""


class HostContext(StackContext, Protocol):
    """`StackContext` and what an external stack's client sends to its server: the run's
    description and the world's ground truth (`stack.bridge`, `stack.osi_stack`)."""

    spec: object  # the RunSpec
    step_s: float
    duration_s: float
    ego_plan: object  # the ego's `bound.BoundActor`
    sensors: dict

    def ego_body(self):
        """(VehicleState, z of the road under the ego [m]) of the ego."""

    def agent_truths(self) -> Iterator[tuple]:
        """(name, vehicle kind, ground truth or None, accel [m/s^2], height [m], z [m], grade)
        of every agent, in declaration order."""

    def agent_names(self) -> list[str]:
        """The agents' names in declaration order."""

    def body_name(self, body: int) -> str | None:
        """The actor a physics body id belongs to."""

    def ego_stop_lines(self) -> list[tuple[str, float, float, float, float]]:
        """(controller, x, y, z, heading) of each stop line on the ego's road or route."""

    def ego_signs(self) -> list[tuple[str, float, float, float, float]]:
        """(kind, x, y, z, lane heading) where each sign's line on the ego's route meets its lane."""

    def light_state(self, controller: str, time_s: float) -> int:
        """A light's state code at `time_s` (`lights`)."""

    def ego_light_stations(self) -> list[tuple[float, str]]:
        """(station [m], controller) of each stop line on the ego's road or route, in path order."""

    def ego_sign_stations(self) -> list[tuple[float, str]]:
        """(station [m], kind) of each sign's line on the ego's road or route, in path order."""

    def ego_route_roads(self) -> list:
        """The map roads of the ego's road or route, in driving order."""


class SensorFrame(Protocol):
    """What a fault and the stack may read of a captured frame (`sensors.Frame`)."""

    sensor: str  # the sensor's name
    stamp_s: float  # capture time [s]
    data: dict  # the measurement: arrays (points, image, ...) and scalars
    ego_pose: tuple | None  # (x, y, heading, speed) of the ego at the capture
    actors: dict | None  # body id -> ground truth at the capture, of the bodies a lidar hit


class FaultSensor(Protocol):
    """What a sensor fault may read and change of its sensor: its name and its mounts
    (`shift` moves the `actual` one; the stack keeps the `nominal` calibration)."""

    name: str
    actual: object  # `sensors.Extrinsics`
    nominal: object


class FaultStack(Protocol):
    """What the fault schedule binds to (`FaultSchedule.bind`; each member optional): the
    stack's nodes with their scalar sites, the sites of their stored state, its tensor
    sites, and, for a stack that applies its internal faults itself, their hand-over."""

    nodes: dict  # node -> its scalar fault sites
    state_nodes: dict  # node -> the sites of its stored state

    def tensor_sites(self) -> dict:
        """site -> the learned model's tensor it names."""

    def take_internal_faults(self, faults: list) -> None:
        """Take the faults that are not a sensor's (an external stack's client sends them on)."""
