"""`execute(RunSpec) -> RunResult`: the only entry point into the runtime.

One discrete loop in simulated time. Each physics step: traffic behaviours and
triggers; sensors that are due capture (after spatial faults), temporal faults decide
when (or whether) the frame reaches the stack; the stack ticks (its nodes publish at
`t + latency`); the latest due command drives the ego dynamics (a scripted ego moves by its behaviours
as agents do, its stack, if any, running open loop); the state is recorded.
Everything random draws from generators seeded by the RunSpec, so the same RunSpec
gives the same trace bit for bit.
"""

from __future__ import annotations

import heapq
import math
import time as _time
import zlib
from collections import Counter
from dataclasses import dataclass

import numpy as np

from addt_dsl.plan import RunSpec
from addt_dsl.registry import BEHAVIORS, ENVIRONMENTS, FAULTS, SENSORS, STACKS
from addt_dsl.runtime import oracles
from addt_dsl.runtime import fleet
from addt_dsl.runtime.behaviors import AgentState, Idm, advance, lateral_profile, relative_heading, standing_yaw
from addt_dsl.runtime.bound import BoundActor, BoundClause, BoundScenario, bind
from addt_dsl.runtime.faults import FaultSchedule
from addt_dsl.runtime.neighbours import LeaderIndex, Member, leader_scan
from addt_dsl.runtime.lights import LightsRuntime, Program, StopStation, next_stop, stations_on, stop_accel, stop_lines
from addt_dsl.runtime.fastroad import FastRoad
from addt_dsl.runtime.path import RoutePath
from addt_dsl.runtime.road import resolve_route
from addt_dsl.runtime.roadmesh import Elevation, build_scene
from addt_dsl.runtime.roadspec import build_network
from addt_dsl.runtime.script import Script
from addt_dsl.runtime.signals import STEP_ENDED, STEP_STARTED, STEP_WAITING, compute_signals
from addt_dsl.runtime.result import RunResult, Verdict, spec_json
from addt_dsl.runtime.trace import ActorTrack, Event, Trace, injection_count
from addt_dsl.runtime.vehicle import VehicleParams, VehicleState
from addt_dsl.runtime.vehicle import step as vehicle_step
from addt_dsl.runtime.world import PhysicsWorld, box_separation, separation
from addt_dsl.vehicles import VEHICLES



class ActorRoad:
    """The road an actor drives on, as a sampled fast view."""

    def __init__(self, network, road_id: str, cache: dict):
        self.network = network
        key = (id(network), road_id)
        if key not in cache:
            cache[key] = (FastRoad(network.road(road_id)), Elevation(network.road(road_id)))
        self.road, self.elevation = cache[key]
        self.road_id = road_id

    def pose(self, s: float, t: float) -> tuple[float, float, float]:
        return self.road.point(s, t)

    def station(self, road_id: str, s: float) -> float:
        return s

    def direction(self, u: float) -> int:
        return 1


class ActorPath(ActorRoad):
    """An actor's route (or a lane driven against s) as one road: `runtime.path.RoutePath`."""

    def __init__(self, network, scenario_road: str, legs, cache: dict):
        self.network = network
        roads = {}
        for leg in legs:
            key = (id(network), leg.road_id)
            if key not in cache:
                cache[key] = (FastRoad(network.road(leg.road_id)), Elevation(network.road(leg.road_id)))
            roads[leg.road_id] = cache[key]
        key = scenario_road + ":" + ";".join(f"{g.road_id}{g.direction:+d}{g.lane}@{g.s_from:g}" for g in legs)
        self.road = RoutePath(key, legs, roads)
        self.elevation = self.road.elevation
        self.road_id = key

    def station(self, road_id: str, s: float) -> float:
        return self.road.station(road_id, s)

    def direction(self, u: float) -> int:
        return self.road.direction(u)


def junction_legs(road: ActorRoad) -> list[tuple[float, float, float, float]]:
    """(entry, exit station [m], conflict point x, y [m]) of each junction leg of a path."""
    if not isinstance(road, ActorPath):
        return []
    out = []
    for leg in road.road.legs:
        r = road.network.road(leg.road_id)
        if r.junction in ("", "-1"):
            continue
        x, y, _ = r.lane_center(leg.lane, 0.5 * (leg.s_from + leg.s_to))
        out.append((road.station(leg.road_id, leg.s_from), road.station(leg.road_id, leg.s_to), float(x), float(y)))
    return out



LANE_SETTINGS = ("to", "lane")  # behaviour settings that name a lane id


def _is_live(clause: BoundClause) -> bool:
    """Whether a behaviour has a setting that reads signals (kept as an expression)."""
    return any(not isinstance(v, (int, float, str, list)) for v in clause.settings.values())


def _stable_seed(*parts) -> list[int]:
    return [int(p) if isinstance(p, int) else zlib.crc32(str(p).encode()) for p in parts]


class _Context:
    """What the stack may see and do (`views.HostContext`): its sensors, the map, the fault
    schedule, the clock, and for an external stack's client the run's ground truth."""

    def __init__(self, run: _Run):
        self._run = run
        self.world = run  # views.PerceptionWorld
        self.faults = run.faults
        self.spec = run.spec
        self.step_s, self.duration_s = run.dt, run.bound.duration_s
        self.ego_plan = run.ego_plan
        self.sensors = run.sensors
        self.now = 0.0
        self.wheelbase_m = run.vehicle_params.wheelbase_m
        ego = run.ego_plan  # the declared body reaches the stack's planner and controller
        self.ego_length_m, self.ego_width_m, self.ego_mass_kg, self.ego_mu = \
            ego.length_m, ego.width_m, ego.mass_kg, ego.mu
        self.ego_lane = run.ego_lane

    def rng(self, name: str) -> np.random.Generator:
        return np.random.default_rng(_stable_seed(self._run.bound.seed, "stack", name))

    def ego_pose(self):
        return self._run.ego_pose()

    def ego_road(self):
        return self._run.ego_road.road, self._run.ego_road.road_id

    def sensor(self, name: str):
        return self._run.sensors[name]

    def junction_ahead(self, s: float):
        """(entry station [m], x, y of its middle [m], exit station [m]) of the next junction
        on the ego's route that its front has not left, or None (no route, or past the last)."""
        front = s + 0.5 * self._run.ego_plan.length_m
        for entry, exit_, cx, cy in self._run.ego_junctions:
            if exit_ > front:
                return entry, cx, cy, exit_
        return None

    def stop_line_ahead(self, s: float):
        """(station [m] on the ego's road or route, state code) of the next traffic light's
        stop line ahead of the ego's front at station `s`, or None: the map and the light's
        state as a connected vehicle would know them (no camera detection of lights)."""
        run = self._run
        if run.lights is None:
            return None
        front = s + 0.5 * run.ego_plan.length_m
        return next_stop(run.stop_stations["ego"], front, lambda c: run.lights.state(c, self.now))

    def ego_station(self) -> float:
        return self._run.ego_s

    def event(self, kind: str, **detail) -> None:
        self._run.events.append(Event(self.now, kind, detail))

    def emit(self, event: Event) -> None:
        self._run.events.append(event)

    def apply_command_at(self, time_s: float, steer: float, accel: float) -> None:
        self._run.command_queue.append((time_s, steer, accel))

    # ---- the ground truth an external stack's client sends (views.HostContext)
    def ego_body(self):
        return self._run.ego, self._run.ego_z

    def agent_names(self) -> list[str]:
        return [a.name for a in self._run.agents]

    def agent_truths(self):
        run = self._run
        for a in run.agents:
            plan = run.agent_plans[a.name]
            z, grade = run.agent_roads[a.name].elevation.at(a.s)
            yield a.name, plan.vehicle, run.fleet.ground_truth(a.name), a.accel, plan.height_m, z, grade

    def body_name(self, body: int) -> str | None:
        return self._run.physics.body_names.get(body)

    def ego_stop_lines(self):
        run = self._run
        if run.lights is None:
            return []
        road, out = run.ego_road, []
        for st in run.stop_stations.get("ego", ()):
            x, y, h = road.pose(st.u, float(road.road.lane_center_t(run.ego_lane, st.u)))
            z, _ = road.elevation.at(st.u)
            out.append((st.controller, x, y, z, h))
        return out

    def light_state(self, controller: str, time_s: float) -> int:
        return self._run.lights.state(controller, time_s)

    def ego_route_roads(self) -> list:
        ego_road = self._run.ego_road
        legs = getattr(ego_road.road, "legs", None)
        ids = list(dict.fromkeys(leg.road_id for leg in legs)) if legs else [ego_road.road_id]
        return [ego_road.network.road(rid) for rid in ids]


LATENCY_NODES = ("perception", "tracker", "planner", "control", "e2e")  # recorded per step


class _NoStack:
    """The stack of a scripted ego that has none: nothing runs, latencies stay 0."""

    nodes: dict = {}

    def __init__(self):
        self.latency = dict.fromkeys(LATENCY_NODES, 0.0)
        self.objects_seen = 0

    def on_frame(self, frame, time_s: float) -> None:
        pass

    def step(self, time_s: float, dt: float) -> None:
        pass


class _Run:
    def __init__(self, spec: RunSpec):
        self.spec = spec
        self.bound = plan = bind(spec)  # every parameter expression evaluated here, once
        self.dt = plan.step_s
        self.n_steps = int(round(plan.duration_s / self.dt))
        self.events: list[Event] = []
        self.left_road = False  # the ego passed the end of its road or route (`left_road` event)
        self.networks = build_network(plan.roads)
        self._road_cache: dict = {}
        # Visual shapes (road meshes, coloured actors) only when a sensor renders.
        visual = any(getattr(SENSORS.get(c.name), "renders", False) for c in plan.ego.sensors)
        self.physics = PhysicsWorld(visual=visual)
        try:
            self._populate(plan)
        except BaseException:
            # Set-up failed (e.g. an unreachable external stack): release what was opened.
            self.close()
            raise

    def _populate(self, plan: BoundScenario) -> None:
        self.scene = build_scene(self.physics, list(self.networks.values()))
        self.faults = FaultSchedule(list(plan.faults), self.dt, plan.duration_s, self.events)
        self.command_queue: list[tuple[float, float, float]] = []
        self.command = (0.0, 0.0)
        self._rngs: dict[str, np.random.Generator] = {}
        self._live_snapshot = None  # (step, state) that live behaviour settings read
        self.behavior_version = 0  # behaviours started so far

        ego = plan.ego
        self.ego_plan = ego
        self.ego_road = self._road_of(ego)
        s0 = self.ego_road.station(self._first_road(ego), ego.s)
        # On a path lane ids are in driving convention (road id x direction).
        self.ego_lane = ego.lane * self.ego_road.direction(s0)
        t0 = float(self.ego_road.road.lane_center_t(self.ego_lane, s0)) + ego.offset
        x, y, h = self.ego_road.pose(s0, t0)
        if ego.yaw:
            h += ego.yaw
        self.vehicle_params = VehicleParams.for_vehicle(ego.mass_kg, ego.wheelbase_m, ego.mu)
        self.ego = VehicleState(x, y, h, ego.speed)
        self.ego_z, self.ego.pitch = 0.0, 0.0
        self.ego_s, self.ego_t = s0, t0
        self.physics.add_box("ego", ego.length_m, ego.width_m, ego.height_m)

        self.agents: list[AgentState] = []
        self.agent_plans: dict[str, BoundActor] = {}
        self.agent_roads: dict[str, ActorRoad] = {}
        self.longitudinal: dict[str, object] = {}
        self.scripts: dict[str, Script] = {}
        self.deferred: list[tuple[AgentState, BoundClause]] = []  # time-0 behaviours with live settings
        # Named steps (agent, `agent.label`, state), whose states are recorded per sample.
        self.named_steps: list[tuple[AgentState, str, object]] = []
        # A scripted ego: an AgentState moved by the agents' code (`_script`), its
        # VehicleState posed from it each step (`_pose_scripted_ego`); None: its stack drives.
        self.ego_agent = None
        if ego.scripted:
            self.ego_agent = AgentState("ego", self.ego_road.road_id, s0, t0, ego.speed, 0.0, ego.length_m,
                                        ego.width_m, self.ego_lane, t0)
            self._script(self.ego_agent, ego, self.ego_road)
        for a in plan.agents:
            road = self._road_of(a)
            u = road.station(self._first_road(a), a.s)
            lane = a.lane * road.direction(u)
            t = float(road.road.lane_center_t(lane, u)) + a.offset
            st = AgentState(a.name, road.road_id, u, t, a.speed, 0.0, a.length_m, a.width_m, lane, t)
            self.agents.append(st)
            self.physics.add_box(a.name, a.length_m, a.width_m, a.height_m, VEHICLES[a.vehicle].rgba)
            self._script(st, a, road)
        self.agent_by_name = {a.name: a for a in self.agents}
        # Members in `occupants` order (agents, then the ego): the order breaks leader ties.
        self.leaders = LeaderIndex([*self.agents, _EgoOccupant(self)])
        # Any actor on a path: agents find their leader by position (across roads), not by road.
        self.networked = isinstance(self.ego_road, ActorPath) or any(
            isinstance(r, ActorPath) for r in self.agent_roads.values())
        self.world_pose: dict[str, tuple[float, float, float]] = {}
        self.fleet = _Fleet(self)
        self.contacts: set[tuple[str, str]] = set()  # actor pairs overlapping at the last step

        self.sensors = {}
        self.sensor_next: dict[str, float] = {}
        for clause in ego.sensors:
            cls = SENSORS.get(clause.name)
            sensor = cls(clause.name, clause.settings)
            self.sensors[clause.name] = sensor
            self.sensor_next[clause.name] = 0.0
        self.environment = [ENVIRONMENTS.get(c.name)(c.settings) for c in plan.environment]
        self.inflight: list[tuple[float, int, object]] = []  # frames in transit to the stack
        self._frame_seq = 0
        self._setup_lights(plan)
        # `end when ...`: a start without a behaviour; the run ends where it fires.
        self.end_script = Script((plan.end,)) if plan.end is not None else None
        self.ego_junctions = junction_legs(self.ego_road)
        self.ctx = _Context(self)
        stack_clause = ego.stack
        if stack_clause is None:  # a scripted ego without a stack
            self.stack = _NoStack()
        else:
            self.stack = STACKS.get(stack_clause.name)(stack_clause.settings, self.ctx)
        # A stack that moves its host itself (an OSI stack answering TrafficUpdates) sets the
        # ego's state in place of the dynamics step: `move_host(state, time_s)`.
        self.move_host = getattr(self.stack, "move_host", None)
        self.faults.bind(self.stack, lambda: self.ctx.now)

    def _script(self, st: AgentState, a: BoundActor, road: ActorRoad) -> None:
        """Start an actor's time-0 behaviours (deferred to the first recorded state when
        one reads signals) and arm its script."""
        self.agent_plans[a.name] = a
        self.agent_roads[a.name] = road
        self.longitudinal[a.name] = None
        if any(_is_live(c) for c in a.behaviors):  # they read the first recorded state
            self.deferred.extend((st, c) for c in a.behaviors)
        else:
            for clause in a.behaviors:
                self._start_behavior(st, clause, 0.0)
        if a.steps:  # (armed also when the behaviours wait for the first state: they start first)
            self.scripts[a.name] = Script(a.steps)
            self.named_steps.extend((st, f"{a.name}.{n.label}", n) for n in self.scripts[a.name].named)

    def move(self, a: AgentState, t_now: float, dt: float) -> None:
        """One step of a kinematic actor: its longitudinal behaviour's acceleration, held
        for red lights on its path (unless it runs them), integrated along its road."""
        beh = self.longitudinal[a.name]
        accel = beh.accel(a, self, t_now) if beh is not None else 0.0
        if self.lights is not None and not a.heading_rel and not self.agent_plans[a.name].ignore_lights:
            accel = self.stop_for_lights(a, accel, t_now)
        advance(a, accel, t_now, dt)

    def _setup_lights(self, plan: BoundScenario) -> None:
        """Traffic lights: each controller's program, the stop lines its signals make, and
        where each actor meets them along its road or route (none: `self.lights` is None)."""
        self.lights: LightsRuntime | None = None
        self.light_script: Script | None = None
        self.stop_stations: dict[str, list[StopStation]] = {}
        if not plan.controllers:
            return
        inline = {sig.name: (sig.road, sig.s_m, tuple(sig.lanes)) for sig in plan.signals}
        # A map's signals stand on the map: roads declared from the same OpenDRIVE file
        # (`road r2 import "m.xodr" road 2`, `road r3 ... road 3`) share its stop lines.
        same_map = {r.name: [o.name for o in plan.roads if o.name == r.name or
                             (r.source == "xodr" and o.source == "xodr" and o.xodr_text == r.xodr_text)]
                    for r in plan.roads}
        lines: dict[str, list] = {}
        for c in plan.controllers:
            found = stop_lines(self.networks[c.road], c.name, c.signals, inline)
            for name in same_map[c.road]:
                lines.setdefault(name, []).extend(found)
        self.lights = LightsRuntime({c.name: Program(c.green_s, c.yellow_s, c.red_s, c.offset_s)
                                     for c in plan.controllers})
        if plan.light_steps:
            self.light_script = Script(plan.light_steps)
        self.stop_stations["ego"] = self._stations(self.ego_road, plan.ego, lines.get(plan.ego.road, []))
        for a in plan.agents:
            self.stop_stations[a.name] = self._stations(self.agent_roads[a.name], a, lines.get(a.road, []))

    @staticmethod
    def _stations(road: ActorRoad, actor: BoundActor, lines) -> list[StopStation]:
        if not lines:
            return []
        if isinstance(road, ActorPath):
            return stations_on(lines, road.road.legs, road.station)
        plain = _PlainLeg(road.road_id, 1, 0.0, float(road.network.road(road.road_id).length), actor.lane)
        return stations_on(lines, [plain], road.station)

    def stop_for_lights(self, agent: AgentState, accel: float, time_s: float) -> float:
        """An agent's acceleration [m/s^2] limited to stop at the next red (or yellow it can
        stop for) light on its path."""
        front = agent.s + 0.5 * agent.length_m
        # Only the next line ahead holds the agent (its most restrictive light).
        nxt = next_stop(self.stop_stations.get(agent.name, ()), front, lambda c: self.lights.state(c, time_s))
        if nxt is not None:
            a_stop = stop_accel(agent.speed, nxt[0] - front, nxt[1])
            if a_stop is not None:
                accel = min(accel, a_stop)
        return accel

    def record_lights(self, lights_rec: dict, margins: dict, k: int, time_s: float) -> None:
        for name in lights_rec:
            lights_rec[name][k] = self.lights.state(name, time_s)
        margins["ego"][k] = self.lights.red_margin("ego", self.ego_s + 0.5 * self.ego_plan.length_m,
                                                   self.stop_stations["ego"], time_s)
        for a in self.agents:
            margins[a.name][k] = self.lights.red_margin(a.name, a.s + 0.5 * a.length_m,
                                                        self.stop_stations[a.name], time_s)

    def close(self) -> None:
        """Release the fault schedule, the pybullet client and the stack's resources."""
        faults = getattr(self, "faults", None)
        if faults is not None:
            faults.close()
        self.physics.close()
        close_stack = getattr(getattr(self, "stack", None), "close", None)  # e.g. the bridge's socket
        if close_stack is not None:
            close_stack()

    # ---- queries used by sensors and the stack
    def _first_road(self, actor: BoundActor) -> str:
        if actor.route:
            return actor.route[0]
        rp = self.bound.road(actor.road)
        return rp.xodr_road_id if rp.source == "xodr" and rp.xodr_road_id else next(iter(self.networks[actor.road].roads))

    def _road_of(self, actor: BoundActor) -> ActorRoad:
        """The plain road (no route, driven along +s), else the actor's path."""
        network = self.networks[actor.road]
        road_id = self._first_road(actor)
        way = -1 if actor.reverse else 1
        if not actor.route and network.road(road_id).travel_direction(actor.lane) * way > 0:
            return ActorRoad(network, road_id, self._road_cache)
        _, legs = resolve_route(network, list(actor.route or (road_id,)), actor.lane, actor.s, reverse=actor.reverse)
        return ActorPath(network, actor.road, legs, self._road_cache)

    def rng(self, name: str) -> np.random.Generator:
        if name not in self._rngs:
            self._rngs[name] = np.random.default_rng(_stable_seed(self.bound.seed, "world", name))
        return self._rngs[name]

    def ego_pose(self):
        e = self.ego
        return e.x, e.y, e.heading, e.speed

    def ego_frame(self):
        """(x, y, z of the road under the ego, heading, pitch nose-up) for sensor mounts."""
        e = self.ego
        return e.x, e.y, self.ego_z, e.heading, e.pitch

    def ego_state(self):
        return self.ego

    def render(self, width, height, view, projection, segmentation=True):
        return self.physics.render(width, height, view, projection, segmentation)

    def actor_station(self, name: str):
        """(s [m], speed [m/s], length [m]) of an actor, or None if there is none."""
        if name == "ego":
            return self.ego_s, self.ego.speed, self.ego_plan.length_m
        a = self.agent_by_name.get(name)
        return None if a is None else (a.s, a.speed, a.length_m)

    def road_coords(self, agent: AgentState, x: float, y: float) -> tuple[float, float]:
        """(s, t) of a world point on an agent's road [m]."""
        return self.agent_roads[agent.name].road.project(x, y, agent.s)

    def from_road_coords(self, agent: AgentState, s: float, t: float) -> tuple[float, float]:
        """An agent's (s, t) [m] of OpenDRIVE road coordinates (`s`, `t`: along the
        reference line, left of +s positive) on the road it is on now. The same on a road
        driven along +s; on a path (a route, a lane driven against s) its station and its
        offset from the route lane's centre, to the driver's left."""
        road = self.agent_roads[agent.name]
        if not isinstance(road, ActorPath):
            return s, t
        road_id = road.road.road_at(agent.s)[0]
        x, y = road.network.road(road_id).point_at(s, t)
        return road.road.project(float(x), float(y), road.road.station(road_id, s))

    def actor_lane(self, name: str) -> int | None:
        """The lane an actor is in now (None off the lanes)."""
        if name == "ego":
            return self.ego_road.road.lane_at(self.ego_s, self.ego_t)
        a = self.agent_by_name[name]
        return self.agent_roads[name].road.lane_at(a.s, a.t)

    def road_band_t(self, road_id: str, s: float) -> tuple[float, float]:
        road = next(r for r in self.agent_roads.values() if r.road_id == road_id)
        return road.road.road_band_t(s)

    def ray_cast(self, starts, ends):
        return self.physics.ray_cast(starts, ends, ignore="ego")

    def actor_by_body(self, body: int):
        return self.fleet.ground_truth(self.physics.body_names.get(body))

    def leader_of(self, agent: AgentState):
        """(gap [m], speed [m/s]) of the nearest actor ahead in the agent's lane, or None
        (`neighbours.leader_scan`'s answer, from the per-road index the loop keeps)."""
        if self.networked:
            return self._leader_by_position(agent)
        return self.leaders.leader(agent)

    def _leader_by_position(self, agent: AgentState, reach_m: float = 150.0):
        """`leader_of` across roads: `neighbours.leader_scan` over every actor within `reach_m`
        projected onto the agent's path (station and offset on it), its speed taken along
        the path."""
        road = self.agent_roads[agent.name].road
        ax, ay, _ = self.world_pose.get(agent.name, road.point(agent.s, agent.t))
        near = []
        for name, (x, y, heading) in self.world_pose.items():
            if name == agent.name or abs(x - ax) > reach_m or abs(y - ay) > reach_m:
                continue
            dist = math.hypot(x - ax, y - ay)
            if dist > reach_m:
                continue
            u, t = road.project(x, y, agent.s + dist)
            near.append(_Projected(name, agent.road, u, t, self, heading, road))
        return leader_scan(near, agent)

    def direction_of(self, agent: AgentState) -> int:
        """+1 / -1: the agent's road direction at its station (its path's, on a route)."""
        return self.agent_roads[agent.name].direction(agent.s)

    def occupants(self, road_id: str):
        """Every actor on a road (`neighbours.Member`), agents in declaration order, then the ego."""
        for a in self.agents:
            if a.road == road_id:
                yield Member(a.name, road_id, a.s, a.t, a.speed, a.length_m)
        if self.ego_road.road_id == road_id:
            yield Member("ego", road_id, self.ego_s, self.ego_t, self.ego.speed, self.ego_plan.length_m)

    def lane_t(self, road_id: str, lane: int, s: float) -> float:
        road = next(r for r in self.agent_roads.values() if r.road_id == road_id)
        return float(road.road.lane_center_t(lane, s))

    # ---- behaviours
    def live_value(self, expr) -> float:
        """A live behaviour setting (`speed(ego) + 5 km/h`) on the state recorded this step."""
        rec, k = self.recorded
        if self._live_snapshot is None or self._live_snapshot[0] != k:
            # Without step states: whether a step ended can itself ask a live setting (a
            # cruise that follows `speed(other)` ends at that speed), which would recurse.
            self._live_snapshot = (k, _snapshot_trace(self, rec, k, with_steps=False))
        trace = self._live_snapshot[1]
        return float(oracles.evaluate(expr, compute_signals(trace, oracles_signals(expr)), self.dt)[0])

    def _start_behavior(self, agent: AgentState, clause: BoundClause, time_s: float):
        cls = BEHAVIORS.get(clause.name)
        settings = clause.settings
        road = self.agent_roads[agent.name]
        if isinstance(road, ActorPath):  # lane ids of settings are the map's: to driving convention
            sign = road.direction(agent.s)
            settings = {k: (v * sign if k in LANE_SETTINGS and isinstance(v, (int, float)) else v)
                        for k, v in settings.items()}
        beh = cls(settings)
        self.behavior_version += 1  # the agents' array step re-reads who may be stepped as arrays
        beh.start(agent, self, time_s)
        if beh.channel == "longitudinal":
            self.longitudinal[agent.name] = beh
        self.events.append(Event(time_s, "behavior", {"actor": agent.name, "behavior": clause.name}))
        return beh

    def behavior_ended(self, agent: AgentState, beh, time_s: float) -> bool:
        """Whether a behaviour a step started has completed; one replaced on the
        longitudinal channel never does (lateral moves check their own, Behavior.ended)."""
        if beh.channel == "longitudinal" and self.longitudinal[agent.name] is not beh:
            return False
        return beh.ended(agent, self, time_s)

    def step_states(self, time_s: float) -> dict[str, int]:
        """The state code of each named step now (signals.STEP_*), ends updated first."""
        out = {}
        for agent, name, step in self.named_steps:
            ended = step.update_end(time_s, lambda beh, t, _a=agent: self.behavior_ended(_a, beh, t))
            out[name] = STEP_ENDED if ended else STEP_STARTED if step.fired else STEP_WAITING
        return out


def execute(spec: RunSpec, keep_trace: bool = True) -> RunResult:
    """Run one RunSpec closed-loop and judge it."""
    wall0 = _time.perf_counter()
    run = _Run(spec)
    try:
        trace = _loop(run)
    finally:
        run.close()
    verdicts = judge(run.bound, trace)
    injections: Counter = Counter()
    drawn_name = {f.index: FAULTS.get(f.kind).drawn_setting for f in spec.faults}
    drawn: dict[int, list[int]] = {}
    for e in trace.events:
        if e.kind == "fault":
            index = e.detail["index"]
            injections[index] += injection_count(e)
            name = drawn_name.get(index)
            if name is not None and name in e.detail:
                drawn.setdefault(index, []).append(int(e.detail[name]))
    return RunResult(
        run_id=spec.run_id, key=spec.key(), spec_json=spec_json(spec), params=dict(spec.params),
        cell=dict(spec.cell), seed=spec.seed, repeat_index=spec.repeat_index, status=trace.status,
        verdicts=verdicts, error=trace.error, sim_time_s=trace.duration_s,
        wall_time_s=_time.perf_counter() - wall0, digest=trace.digest(), fault_events=sum(injections.values()),
        injections=dict(injections), drawn_values={k: tuple(v) for k, v in drawn.items()},
        trace=trace if keep_trace else None)


def _loop(run: _Run) -> Trace:
    plan, dt = run.bound, run.dt
    n = run.n_steps + 1
    names = ["ego"] + [a.name for a in run.agents]
    # One block [sample, actor, field]: a step's state goes in as one row (per-value numpy
    # stores cost ~0.1 us each, 11 per actor per step); rec[name][field] are its columns.
    block = np.zeros((n, len(names), len(_FIELDS)))
    rec = {name: {f: block[:, i, j] for j, f in enumerate(_FIELDS)} for i, name in enumerate(names)}
    lat_nodes = LATENCY_NODES
    latency = {k: np.zeros(n) for k in lat_nodes}
    outputs = {"control.steer": np.zeros(n), "control.accel": np.zeros(n)}
    objects = np.zeros(n)
    steps = {name: np.zeros(n, dtype=np.int8) for _, name, _ in run.named_steps}
    status, error = "ok", ""
    last = n
    sizes = {"ego": (plan.ego.length_m, plan.ego.width_m)}
    sizes.update({a.name: (a.length_m, a.width_m) for a in run.agents})
    ego_road = run.ego_road
    leaders_stale = False  # the leader index missed an array step: rebuilt before it is asked
    lights_rec = {c.name: np.zeros(n) for c in plan.controllers} if run.lights else {}
    margins = {name: np.zeros(n) for name in names} if run.lights else {}
    agents, fleet_ = run.agents, run.fleet
    lengths = [sizes[n][0] for n in names]
    widths = [sizes[n][1] for n in names]
    if len(names) > _ALL_PAIRS_MAX:  # the broad phase's arrays
        lengths, widths = np.array(lengths), np.array(widths)
    # Few agents (most runs): posed, recorded and checked one by one in straight-line code
    # below; the fleet's lists, arrays and calls cost more than they save there.
    few = len(agents) < ARRAY_MIN_AGENTS
    if few:
        # Per agent, fixed for the run: (state, road, extra yaw [rad], half its body height [m],
        # vehicle kind, length [m], width [m]).
        agent_consts = [(a, run.agent_roads[a.name], run.agent_plans[a.name].yaw,
                         run.agent_plans[a.name].height_m / 2,
                         run.agent_plans[a.name].vehicle, a.length_m, a.width_m) for a in agents]
        set_pose, body_actor, world_pose = run.physics.set_pose, fleet_.body_actor, run.world_pose
        networked = run.networked
        ego_size = sizes["ego"]

    for k in range(n):
        t_now = k * dt
        run.ctx.now = t_now
        if t_now + 1e-12 >= run.faults.next_wake_s:  # fault timers (tensor hooks attach at their instants)
            run.faults.wake(t_now)
        # Agent poses (kinematic along their road), for the physics world and perception.
        if few:
            row, boxes = [None], [None]  # the ego's first, below
            for a, road, yaw, half_height, kind, length, width in agent_consts:
                x, y, h = road.road.point(a.s, a.t)
                a.ground_scale = road.road.ground_scale(a.s, a.t)
                heading = h + relative_heading(a, t_now, dt)
                if yaw:
                    heading += standing_yaw(a, yaw)
                z, grade = road.elevation.at(a.s)
                set_pose(a.name, x, y, z + half_height, heading, math.atan(grade) * math.cos(heading - h))
                body_actor[a.name] = (x, y, heading, a.speed, length, width, kind)
                row.append((x, y, heading, a.speed, a.accel, 0.0, a.s, a.t, road.road.lane_offset(a.s, a.t), 0.0))
                boxes.append((x, y, heading, length, width))
                if networked:
                    world_pose[a.name] = (x, y, heading)
        elif agents:
            fleet_.pose(run, t_now, dt)
        e = run.ego
        if run.ego_agent is None:
            run.ego_s, run.ego_t = ego_road.road.project(e.x, e.y, run.ego_s)
        else:
            _pose_scripted_ego(run, t_now, dt)
        if run.ego_s >= ego_road.road.length and not run.left_road:
            # Past the end of its road or route: `s` stays at the end, the map has nothing
            # beyond, and the run goes on off the map. Say so once (a route through the
            # junction keeps the ego on the network); from then on it is in no lane: its
            # `lane_offset` is unknown (NaN), which fails `stay in lane`.
            rx, ry, h = ego_road.road.reference_pose(run.ego_s)
            if (e.x - rx) * math.cos(h) + (e.y - ry) * math.sin(h) > 0.5 * plan.ego.length_m:
                run.left_road = True
                run.events.append(Event(t_now, "left_road", {"actor": "ego", "road": plan.ego.road,
                                                             "s": round(float(run.ego_s), 3)}))
        if not run.networked and not leaders_stale:  # (networked runs find leaders by position)
            run.leaders.moved(len(run.agents))  # the ego, last member; agents move below
        # The ego follows the road height; its dynamics feel the grade along its heading.
        z, grade = ego_road.elevation.at(run.ego_s)
        if grade:
            grade *= math.cos(e.heading - ego_road.road.reference_pose(run.ego_s)[2])
        run.ego_z, e.pitch = z, math.atan(grade)
        run.physics.set_pose("ego", e.x, e.y, z + plan.ego.height_m / 2, e.heading, e.pitch)
        if run.networked:
            run.world_pose["ego"] = (e.x, e.y, e.heading)

        # Record the state at t_now (clearance, the last field, below).
        ego_row = (e.x, e.y, e.heading, e.speed, e.accel, e.yaw_rate, run.ego_s, run.ego_t,
                   math.nan if run.left_road else ego_road.road.lane_offset(run.ego_s, run.ego_t), e.steer)
        if few:
            row[0] = ego_row
            block[k, :, :-1] = row
            boxes[0] = (e.x, e.y, e.heading, *ego_size)
        elif fleet_.rows is not None:  # agents posed one by one: the rows at once
            block[k, :, :-1] = [ego_row, *fleet_.rows]
        else:
            block[k, 0, :-1] = ego_row
            fleet_.record(block[k, 1:])
        if run.lights is not None:
            if run.light_script is not None:  # light changes fire on the state just recorded
                _advance_light_script(run, rec, k, t_now)
            run.record_lights(lights_rec, margins, k, t_now)
        xs, ys, hs = ([box[c] for box in boxes] for c in range(3)) if few else fleet_.columns(e)
        collided = _clearances(block[k, :, -1], names, xs, ys, hs, lengths, widths, run, t_now)
        for node in lat_nodes:
            latency[node][k] = run.stack.latency[node]
        outputs["control.steer"][k] = run.command[0]
        outputs["control.accel"][k] = run.command[1]
        objects[k] = run.stack.objects_seen
        if steps:  # named steps: ended on the state just recorded
            for name, code in run.step_states(t_now).items():
                steps[name][k] = code
        ended = False
        if run.end_script is not None:  # `end when ...`, on the state just recorded
            run.end_script.advance(t_now, _condition_checker(run, rec, k), lambda clause, time_s: None)
            if run.end_script.done:
                ended = True
                run.events.append(Event(t_now, "end", {}))
        if collided or ended or k == n - 1:
            last = k + 1
            break

        run.recorded = (rec, k)  # live behaviour settings read the state just recorded
        if run.deferred:
            for agent, clause in run.deferred:
                run._start_behavior(agent, clause, t_now)
            run.deferred.clear()
        # Scripted steps fire on the state just recorded.
        if run.scripts:
            _advance_scripts(run, rec, k, t_now)
            if steps:  # steps that fired now are started at this sample
                for name, code in run.step_states(t_now).items():
                    steps[name][k] = code

        # Sensors → faults → transit to the stack.
        try:
            for name, sensor in run.sensors.items():
                if t_now + 1e-9 < run.sensor_next[name]:
                    continue
                run.sensor_next[name] += sensor.period_s
                for f in run.faults.for_target(name):
                    f.before_capture(sensor, t_now)
                frame = sensor.capture(run, t_now)
                for env in run.environment:  # weather and light act on what the sensor captured
                    frame = env.on_frame(sensor, frame, run.rng(f"environment:{env.keyword}:{name}"))
                delay = 0.0
                for f in run.faults.for_target(name):
                    frame, extra = f.on_frame(frame, t_now)
                    delay += extra
                    if frame is None:
                        break
                if frame is not None:
                    run._frame_seq += 1
                    heapq.heappush(run.inflight, (t_now + delay, run._frame_seq, frame))
            while run.inflight and run.inflight[0][0] <= t_now + 1e-12:
                arrive, _, frame = heapq.heappop(run.inflight)
                run.stack.on_frame(frame, t_now)
            run.stack.step(t_now, dt)
        except Exception as exc:  # noqa: BLE001 - a stack failure is an outcome, not a crash
            status, error = "detected", f"{type(exc).__name__}: {exc}"
            run.events.append(Event(t_now, "stack_error", {"error": error}))
            last = k + 1
            break

        # Commands become effective at their publish time.
        queue = run.command_queue
        while queue and queue[0][0] <= t_now + 1e-12:
            _, steer, accel = queue.pop(0)
            run.command = (steer, accel)
        if run.ego_agent is None and run.move_host is not None:
            run.move_host(run.ego, t_now + dt)
        elif run.ego_agent is None:
            vehicle_step(run.ego, run.vehicle_params, run.command[0], run.command[1], dt, grade)
        else:  # a scripted ego moves as agents do; a stack's commands are recorded, not applied
            if leaders_stale and not run.networked:  # it may ask for its leader
                run.leaders.rebuild()
                leaders_stale = False
            run.move(run.ego_agent, t_now, dt)
            run.ego.vx, run.ego.accel = run.ego_agent.speed, run.ego_agent.accel
        if not all(math.isfinite(v) for v in (run.ego.x, run.ego.y, run.ego.vx)):
            status, error = "detected", "vehicle state became non-finite"
            last = k + 1
            break
        if not few and agents and fleet_.step(run, t_now, dt):  # all at once, as arrays
            leaders_stale = True
            continue
        leaders, networked = run.leaders, run.networked
        if leaders_stale and not networked:
            leaders.rebuild()
            leaders_stale = False
        for i, a in enumerate(agents):
            run.move(a, t_now, dt)
            if not networked:  # agents later in the order see this one where it is now
                leaders.moved(i)

    time = np.arange(last) * dt
    actors = {}
    frames = {"ego": run.ego_road.road_id}
    frames.update({a.name: run.agent_roads[a.name].road_id for a in run.agents})
    for name in names:
        r = rec[name]
        length, width = sizes[name]
        actors[name] = ActorTrack(name, length, width, **{f: np.ascontiguousarray(v[:last]) for f, v in r.items()},
                                  frame=frames[name])
    return Trace(dt, time, actors, {k: v[:last] for k, v in latency.items()}, run.events,
                 {k: v[:last] for k, v in outputs.items()}, objects[:last], status, error,
                 steps={k: v[:last] for k, v in steps.items()},
                 lights={k: v[:last] for k, v in lights_rec.items()}, red_margin={k: v[:last] for k, v in margins.items()})


class _Projected:
    """An actor projected onto another's path (`_Run._leader_by_position`): its speed
    along the path is computed only when it is the leader."""

    __slots__ = ("name", "road", "s", "t", "_run", "_heading", "_path")

    def __init__(self, name, road, s, t, run, heading, path):
        self.name, self.road, self.s, self.t = name, road, s, t
        self._run, self._heading, self._path = run, heading, path

    @property
    def length_m(self) -> float:
        run = self._run
        return run.ego_plan.length_m if self.name == "ego" else run.agent_by_name[self.name].length_m

    @property
    def speed(self) -> float:
        run = self._run
        speed = run.ego.speed if self.name == "ego" else run.agent_by_name[self.name].speed
        return speed * math.cos(self._heading - self._path.reference_pose(self.s)[2])


class _EgoOccupant:
    """The ego as a member of the leader index: its station and offset as projected at
    the start of the step, its speed live (the dynamics step before the agents move)."""

    name = "ego"

    def __init__(self, run: _Run):
        self._run = run
        self.road = run.ego_road.road_id
        self.length_m = run.ego_plan.length_m

    @property
    def s(self) -> float:
        return self._run.ego_s

    @property
    def t(self) -> float:
        return self._run.ego_t

    @property
    def speed(self) -> float:
        return self._run.ego.speed


# Agents posed as arrays from this many on, and stepped as arrays from STEP_MIN_AGENTS on:
# fewer, and the loop's straight-line per-agent code is quicker (posing: ~30 us of numpy
# calls against ~2 us per agent, measured break-even at ~24 agents; the array step asks two leader lookups of ~30 numpy calls each per step, a
# sorted-list bisect per agent costs ~2.5 us: measured break-even at 65-75 agents).
ARRAY_MIN_AGENTS = 24
STEP_MIN_AGENTS = 64


class _Fleet:
    """The agents as arrays for the loop: each step's poses, road points and recorded
    rows computed for all agents at once (numpy over agents), and the longitudinal step
    of car-following agents (`fleet.step` below), with the floats of the per-agent code.

    The `AgentState` objects stay the agents' state (behaviours, scripts and oracles read
    them): a step gathers their stations, offsets and speeds into arrays and, when it
    steps them as arrays, writes the new values back."""

    def __init__(self, run: _Run):
        agents = self.agents = run.agents
        n = self.n = len(agents)
        self.index = {a.name: i for i, a in enumerate(agents)}
        self.roads = [run.agent_roads[a.name] for a in agents]
        groups: dict[int, tuple] = {}
        self.path_rows = []  # agents on a route: posed one by one (RoutePath)
        for i, road in enumerate(self.roads):
            if isinstance(road, ActorPath):
                self.path_rows.append(i)
            else:
                groups.setdefault(id(road.road), (road.road, road.elevation, []))[2].append(i)
        self.groups = [(fast, elev, slice(None) if len(rows) == n else np.array(rows))
                       for fast, elev, rows in groups.values()]
        plans = [run.agent_plans[a.name] for a in agents]
        self.yaws = [p.yaw for p in plans]
        self.yaw = [(i, p.yaw) for i, p in enumerate(plans) if p.yaw]
        self.half_height_m = [p.height_m / 2 for p in plans]
        self.half_height = np.array(self.half_height_m)
        self.kinds = [p.vehicle for p in plans]
        self.length = np.array([a.length_m for a in agents])
        slots = run.physics.box_slots([a.name for a in agents])
        contiguous = bool(slots) and slots == list(range(slots[0], slots[0] + n))
        self.slots = slice(slots[0], slots[0] + n) if contiguous else np.array(slots, dtype=np.intp)
        codes: dict[str, int] = {}
        self.road_code = np.array([codes.setdefault(a.road, len(codes)) for a in agents], dtype=np.int64)
        self.ego_code = codes.setdefault(run.ego_road.road_id, len(codes))
        self.views = fleet.Views(self.length, self.road_code, run.ego_plan.length_m, self.ego_code) if n else None
        self.posed = False
        self.x, self.y, self.heading = [], [], []
        self.rows = [] if n == 0 else None  # the agents' row fields as lists of floats, when posed one by one
        # name -> (x, y, heading, speed, length, width, kind) of an agent posed by the loop's
        # few-agent code (which poses without the fleet)
        self.body_actor: dict[str, tuple] = {}
        self._posed_version = -1
        self._plan_version = -1
        self._plan = None

    def gather(self) -> None:
        """Stations, offsets, speeds and accelerations of the agents now."""
        agents = self.agents
        self.s = np.array([a.s for a in agents], dtype=float)
        self.t = np.array([a.t for a in agents], dtype=float)
        self.v = np.array([a.speed for a in agents], dtype=float)

    def pose(self, run: _Run, t_now: float, dt: float) -> None:
        """Pose every agent on its road (`road.point`, the relative heading of a lane change
        or a walk, the extra yaw, the elevation) and hand the poses to the physics world;
        keep them, and each agent's lane offset, for the row."""
        agents, n = self.agents, self.n
        self._posed_version = -1
        if n < ARRAY_MIN_AGENTS:
            self._pose_one_by_one(run, t_now, dt)  # few agents: the per-agent calls are quicker
        else:
            self.gather()
            self.accel = np.array([a.accel for a in agents], dtype=float)
            if np.isfinite(self.s).all() and np.isfinite(self.t).all():
                self._pose_arrays(run, t_now, dt)
                self._posed_version = run.behavior_version  # nothing else moves agents before their step
            else:
                self._pose_one_by_one(run, t_now, dt)
        self.posed = True
        if run.networked:
            for a, xi, yi, hi in zip(agents, self.x, self.y, self.heading):
                run.world_pose[a.name] = (float(xi), float(yi), float(hi))

    def _pose_one_by_one(self, run: _Run, t_now: float, dt: float) -> None:
        """The per-agent code: poses, and the rows as lists of floats."""
        set_pose = run.physics.set_pose
        x, y, heading, v, rows = [], [], [], [], []
        for a, road, yaw, half_height in zip(self.agents, self.roads, self.yaws, self.half_height_m):
            xi, yi, h = road.road.point(a.s, a.t)
            a.ground_scale = road.road.ground_scale(a.s, a.t)
            z, grade = road.elevation.at(a.s)
            off = road.road.lane_offset(a.s, a.t)
            hi = h + relative_heading(a, t_now, dt)
            if yaw:
                hi += standing_yaw(a, yaw)
            set_pose(a.name, xi, yi, z + half_height, hi, math.atan(grade) * math.cos(hi - h))
            x.append(xi), y.append(yi), heading.append(hi), v.append(a.speed)
            rows.append((xi, yi, hi, a.speed, a.accel, 0.0, a.s, a.t, off, 0.0))
        self.x, self.y, self.heading, self.v, self.rows = x, y, heading, v, rows

    def columns(self, ego: VehicleState):
        """(x, y, heading) of every actor, the ego first: lists or arrays as posed."""
        if self.rows is not None:
            return [ego.x, *self.x], [ego.y, *self.y], [ego.heading, *self.heading]
        return tuple(np.concatenate(([v], a)) for v, a in ((ego.x, self.x), (ego.y, self.y), (ego.heading, self.heading)))

    def _road_pose(self, i: int):
        """(x, y, road heading, lane offset, z, grade) of agent i, one by one."""
        a, road = self.agents[i], self.roads[i]
        x, y, h = road.road.point(a.s, a.t)
        z, grade = road.elevation.at(a.s)
        return x, y, h, road.road.lane_offset(a.s, a.t), z, grade

    def _pose_arrays(self, run: _Run, t_now: float, dt: float) -> None:
        """`_pose_one_by_one` as arrays (numpy over agents), bit for bit: the road points
        and lane offsets of each road's agents at once (`FastRoad.points`), and the scalar
        calls only where an agent turns off its road's heading or the road is not flat."""
        agents, n, s, t = self.agents, self.n, self.s, self.t
        rel = np.zeros(n)
        plan = self._array_plan(run)  # with one, only lane changes turn agents off their road's heading
        lateral = plan[2] if plan is not None else \
            [i for i, a in enumerate(agents) if a.heading_rel or a.lc_duration_s > 0.0]
        for i in lateral:
            rel[i] = relative_heading(agents[i], t_now, dt)
        x, y, ref_h, lane_off = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
        z, grade, scale = np.zeros(n), np.zeros(n), np.ones(n)
        for fast, elev, rows in self.groups:
            sr, tr = s[rows], t[rows]
            x[rows], y[rows], ref_h[rows], i, u = fast.points(sr, tr)
            scale[rows] = fast.ground_scales(sr, tr, i, u)
            lane_off[rows] = fast.lane_offsets(sr, tr, i, u)
            zg = elev.at_arrays(sr)
            if zg is not None:
                z[rows], grade[rows] = zg
        for i in self.path_rows:  # routes: one by one
            x[i], y[i], ref_h[i], lane_off[i], z[i], grade[i] = self._road_pose(i)
            scale[i] = self.roads[i].road.ground_scale(float(s[i]), float(t[i]))
        for a, g in zip(agents, scale.tolist()):
            a.ground_scale = g
        heading = ref_h + rel
        for i, yaw in self.yaw:
            heading[i] += standing_yaw(agents[i], yaw)
        pitch = np.zeros(n)  # atan(0) * cos(0) where flat and along the road
        for i in np.flatnonzero((grade != 0.0) | (heading != ref_h)).tolist():
            pitch[i] = math.atan(grade[i]) * math.cos(heading[i] - ref_h[i])
        run.physics.set_poses(self.slots, x, y, z + self.half_height, heading, pitch)
        self.x, self.y, self.heading, self.lane_offset, self.rows = x, y, heading, lane_off, None

    def record(self, row: np.ndarray) -> None:
        """The agents' fields of a step's row (`_FIELDS` but the clearance; yaw rate and
        steer stay 0)."""
        if self.rows is not None:
            row[:, :-1] = self.rows
            return
        zero = np.zeros(self.n)
        row[:, :9].T[:] = (self.x, self.y, self.heading, self.v, self.accel, zero, self.s, self.t, self.lane_offset)

    def ground_truth(self, name: str | None):
        """An agent as perception's ground truth sees it (pose of the step, speed then)."""
        pose = self.body_actor.get(name)  # posed by the loop's few-agent code
        if pose is not None:
            return _GT(*pose)
        i = self.index.get(name)
        if i is None or not self.posed:
            return None
        a = self.agents[i]
        return _GT(float(self.x[i]), float(self.y[i]), float(self.heading[i]), float(self.v[i]),
                   a.length_m, a.width_m, self.kinds[i])

    def _array_plan(self, run: _Run):
        """(IDM settings, their rows, rows in a lane change, lateral targets) when every
        agent can be stepped as arrays now, else None. Re-read when a behaviour starts."""
        if run.behavior_version == self._plan_version:
            return self._plan
        self._plan_version, self._plan = run.behavior_version, None
        if run.networked or run.lights is not None or self.n < max(ARRAY_MIN_AGENTS, STEP_MIN_AGENTS):
            return None
        rows, settings = [], []
        for i, a in enumerate(self.agents):
            beh = run.longitudinal[a.name]
            if a.heading_rel:
                return None
            if beh is None:
                continue
            if type(beh) is not Idm or not all(isinstance(v, (int, float)) for v in beh.settings.values()):
                return None
            rows.append(i)
            settings.append(beh.settings)
        changing = [i for i, a in enumerate(self.agents) if a.lc_duration_s > 0.0]
        target = np.array([a.t_target for a in self.agents], dtype=float)
        self._plan = (fleet.idm_params(settings), slice(None) if len(rows) == self.n else np.array(rows, dtype=np.intp),
                      changing, target)
        return self._plan

    def step(self, run: _Run, t_now: float, dt: float) -> bool:
        """Advance every agent as the per-agent loop would (in declaration order, each
        seeing the earlier ones moved), as arrays; False (nothing changed) where the agents'
        behaviours or states leave it to that loop."""
        plan = self._array_plan(run)
        if plan is None:
            return False
        params, rows, changing, target = plan
        if run.behavior_version != self._posed_version:  # a behaviour started since the poses: read anew
            self.gather()
        s, t, v = self.s, self.t, self.v
        ego = (run.ego_s, run.ego_t, run.ego.speed)
        if not (np.isfinite(s).all() and np.isfinite(t).all() and math.isfinite(ego[0]) and math.isfinite(ego[1])):
            return False
        scale = np.array([a.ground_scale for a in self.agents], dtype=float)
        t_new = target.copy()
        for i in changing:
            t_new[i] = lateral_profile(self.agents[i], t_now + dt)
        views, length = self.views, self.length
        free = fleet.idm_free(params, v if isinstance(rows, slice) else v[rows])
        accel = self._accel(params, rows, v, free, views.leaders(views.jacobi(s, t, v, ego), s, t, length))
        for _ in range(fleet.MAX_ROUNDS):
            v_new = v + accel * dt
            v_new = np.where(v_new > 0.0, v_new, 0.0)  # max(0.0, v), as `advance` picks
            # as `advance`: the station moves by speed / ground_scale, less what a lane change
            # takes across the road
            step, across = v_new * dt, t_new - t
            step = np.where(across != 0.0, np.sqrt(np.maximum(step * step - across * across, 0.0)), step)
            s_new = s + step / scale
            table = views.sequential(s, t, v, (s_new, t_new, v_new), ego)
            again = self._accel(params, rows, v, free, views.leaders(table, s, t, length))
            if np.array_equal(again.view(np.int64), accel.view(np.int64)):  # the fixed point: write it back
                for a, ai, vi, si, ti in zip(self.agents, accel.tolist(), v_new.tolist(), s_new.tolist(),
                                             t_new.tolist()):
                    a.accel, a.speed, a.s, a.t = ai, vi, si, ti
                return True
            accel = again
        return False

    @staticmethod
    def _accel(params, rows, v, free, answer) -> np.ndarray:
        found, gap, speed = answer
        if isinstance(rows, slice):
            return fleet.idm_accel(params, v, free, found, gap, speed)
        accel = np.zeros(len(v))  # no longitudinal behaviour: 0
        accel[rows] = fleet.idm_accel(params, v[rows], free, found[rows], gap[rows], speed[rows])
        return accel


@dataclass(frozen=True)
class _PlainLeg:
    """A road driven along +s from end to end, as a route leg (`stations_on`)."""

    road_id: str
    direction: int
    s_from: float
    s_to: float
    lane: int


@dataclass
class _GT:
    x: float
    y: float
    heading: float
    speed: float
    length_m: float
    width_m: float
    kind: str = ""  # the actor's vehicle kind (addt_dsl.vehicles)


# The recorded fields of an actor, in the order of a step's row; clearance last.
_FIELDS = ("x", "y", "heading", "speed", "accel", "yaw_rate", "s", "t", "lane_offset", "steer", "clearance")


def _pair_separation(a, b, box_a, box_b, reach_a, reach_b) -> float:
    """Separation [m] of two actors' boxes: their centre distance less their half-diagonals
    when that is over 5 m (cheap, a lower bound of the boxes' gap), else exact (SAT)."""
    dist = math.hypot(box_a[0] - box_b[0], box_a[1] - box_b[1])
    r = reach_a + reach_b
    return dist - r if dist > r + 5.0 else box_separation(box_a, box_b)


def _clearances(out, names, x, y, heading, length, width, run, t_now) -> bool:
    """Record each actor's clearance in `out` (names' order; x, y, heading, length and width
    are arrays in that order); a collision event when two boxes start to overlap (any pair,
    agents included). Returns True if the ego is in a collision (the run ends).

    Each actor's clearance is its least separation over all pairs (`_pair_separation`).
    A numpy broad phase over all pairs finds the pairs that can matter (those near enough
    for the exact test, and those whose approximate separation is within a tolerance of
    an actor's least); only these are evaluated, with the arithmetic of the all-pairs
    loop (elementwise in numpy, hypot, sin and cos from `math`), so the figures are those
    of visiting every pair."""
    i, j, sep, clear = _pair_separations(run, names, x, y, heading, length, width)
    collided = False
    touching = set()
    for p in [p for p, value in enumerate(sep.tolist() if isinstance(sep, np.ndarray) else sep)
              if value <= 0.0]:  # in all-pairs order
        a, b = names[i[p]], names[j[p]]
        touching.add((a, b))
        if (a, b) not in run.contacts:
            run.events.append(Event(t_now, "collision", {"actors": [a, b]}))
        if a == "ego" or b == "ego":
            collided = True
    run.contacts = touching
    out[:] = [c if math.isfinite(c) else 1e3 for c in (clear.tolist() if isinstance(clear, np.ndarray) else clear)]
    return collided


def _floats(values) -> list:
    return values.tolist() if isinstance(values, np.ndarray) else values


def _all_pairs(x, y, heading, length, width, reach=None):
    """Every pair one by one: (i, j, separation of each pair, each actor's least);
    `reach`: each actor's half-diagonal [m] (computed when not given)."""
    boxes = list(zip(*(_floats(v) for v in (x, y, heading, length, width))))
    if reach is None:
        reach = [0.5 * math.hypot(b[3], b[4]) for b in boxes]
    n = len(boxes)
    clear = [math.inf] * n
    iu, ju, seps = [], [], []
    for a in range(n):
        box_a, reach_a = boxes[a], reach[a]
        for b in range(a + 1, n):
            sep = _pair_separation(None, None, box_a, boxes[b], reach_a, reach[b])
            if sep < clear[a]:
                clear[a] = sep
            if sep < clear[b]:
                clear[b] = sep
            iu.append(a)
            ju.append(b)
            seps.append(sep)
    return iu, ju, seps, clear


# Broad-phase slack [m]: sqrt(dx^2 + dy^2) differs from math.hypot by ulps, far below this.
_BROAD_SLACK_M = 1e-6
_FEW_BOX_TESTS = 8  # up to this many box tests one by one, more as arrays
_ALL_PAIRS_MAX = 24  # up to this many actors every pair one by one (measured: quicker than numpy)


def _pair_separations(run, names, x, y, heading, length, width):
    """(i, j, separation [m]) of the pairs near enough for the box test (every contact is
    among them), in all-pairs order (i < j over `names`), and each actor's clearance: its
    least separation over all pairs (`_all_pairs` when a pose is not finite or there are
    few actors)."""
    n = len(names)
    if n <= _ALL_PAIRS_MAX:  # few actors: every pair, one by one, is quicker
        reach = getattr(run, "clearance_reach", None)
        if reach is None or len(reach) != n:  # sizes are fixed: once per run
            reach = run.clearance_reach = [0.5 * math.hypot(a, b) for a, b in zip(_floats(length), _floats(width))]
        return _all_pairs(x, y, heading, length, width, reach)
    x, y, heading = np.asarray(x, dtype=float), np.asarray(y, dtype=float), np.asarray(heading, dtype=float)
    # A pose not finite (or so far out that squares overflow): every pair.
    if not ((np.abs(x) < 1e100).all() and (np.abs(y) < 1e100).all() and np.isfinite(heading).all()):
        return _all_pairs(x, y, heading, length, width)
    pairs = getattr(run, "clearance_pairs", None)
    if pairs is None or len(pairs[0]) != n * (n - 1) // 2:  # sizes are fixed: once per run
        reach = np.array([0.5 * math.hypot(a, b) for a, b in zip(length.tolist(), width.tolist())])
        iu, ju = np.triu_indices(n, 1)
        r = reach[iu] + reach[ju]
        run.clearance_pairs = pairs = (iu, ju, r, r + 5.0)
    iu, ju, r, r_exact = pairs
    dx, dy = x[iu] - x[ju], y[iu] - y[ju]
    d = np.sqrt(dx * dx + dy * dy)
    slack = _BROAD_SLACK_M * (1.0 + d)
    close = d <= r_exact + slack
    near = np.flatnonzero(close)  # the exact test may apply
    sep = d - r
    trig = []  # per actor (cos, sin) of the heading, from math, when a box test needs them
    sep[near] = _exact_separations(near, dx, dy, iu, ju, r, r_exact, x, y, heading, length, width, trig)
    table = np.full((n, n), np.inf)
    table[iu, ju] = sep
    table[ju, iu] = sep
    least = table.min(axis=1)
    # Pairs whose approximate separation is within the slack of an actor's least: exact
    # too. The others are farther than every actor's least by more than the slack, so the
    # least over the table then is the least over exact values.
    extra = np.flatnonzero(~close & (sep <= np.maximum(least[iu], least[ju]) + 2.0 * slack))
    if len(extra):
        value = _exact_separations(extra, dx, dy, iu, ju, r, r_exact, x, y, heading, length, width, trig)
        table[iu[extra], ju[extra]] = value
        table[ju[extra], iu[extra]] = value
        least = table.min(axis=1)
    return iu[near], ju[near], sep[near], least


def _exact_separations(p, dx, dy, iu, ju, r, r_exact, x, y, heading, length, width, trig) -> np.ndarray:
    """`_pair_separation` of pairs `p`, bit for bit: math.hypot of the centres, and where
    they are within reach + 5 m the separating-axis test of `world.box_separation`,
    written elementwise in its order."""
    dist = np.fromiter(map(math.hypot, dx[p].tolist(), dy[p].tolist()), float, len(p))
    out = dist - r[p]
    boxed = np.flatnonzero(~(dist > r_exact[p]))
    if 0 < len(boxed) <= _FEW_BOX_TESTS:  # a few: one by one (numpy's calls cost more)
        cols = [_floats(v) for v in (x, y, heading, length, width)]
        for k, a, b in zip(boxed.tolist(), iu[p[boxed]].tolist(), ju[p[boxed]].tolist()):
            out[k] = box_separation(tuple(c[a] for c in cols), tuple(c[b] for c in cols))
    elif len(boxed):
        if not trig:
            hl = heading.tolist()
            trig[:] = [np.fromiter(map(math.cos, hl), float, len(hl)), np.fromiter(map(math.sin, hl), float, len(hl))]
        cos_h, sin_h = trig
        a, b = iu[p[boxed]], ju[p[boxed]]
        out[boxed] = separation(x[b] - x[a], y[b] - y[a], cos_h[a], sin_h[a], cos_h[b], sin_h[b],
                                length[a], width[a], length[b], width[b], _maximum)
    return out


def _maximum(a, b, c, d) -> np.ndarray:
    """`max` of four arrays, elementwise, in `max`'s order (finite values)."""
    return np.maximum(np.maximum(np.maximum(a, b), c), d)


def _condition_checker(run: _Run, rec, k: int):
    """`holds(condition)` on the state recorded at sample k; the trace snapshot is built
    once, at the first condition asked for."""
    snapshot = None

    def holds(condition) -> bool:
        nonlocal snapshot
        if snapshot is None:
            snapshot = _snapshot_trace(run, rec, k)
        sig = compute_signals(snapshot, oracles_signals(condition))
        return bool(oracles.satisfied(condition, sig, run.dt))

    return holds


def _pose_scripted_ego(run: _Run, t_now: float, dt: float) -> None:
    """The scripted ego's pose from its road-frame state, as an agent is posed (heading
    along its road plus a lane change's or walk's relative heading and its yaw)."""
    a, e, road = run.ego_agent, run.ego, run.ego_road.road
    x, y, h = road.point(a.s, a.t)
    a.ground_scale = road.ground_scale(a.s, a.t)  # its station moves by speed / ground_scale, as an agent's
    yaw = run.ego_plan.yaw
    e.x, e.y, e.heading = x, y, h + relative_heading(a, t_now, dt) + (standing_yaw(a, yaw) if yaw else 0.0)
    e.vx, e.accel = a.speed, a.accel
    run.ego_s, run.ego_t = a.s, a.t


def _advance_scripts(run: _Run, rec, k: int, t_now: float) -> None:
    holds = _condition_checker(run, rec, k)

    for name, script in list(run.scripts.items()):
        agent = run.ego_agent if name == "ego" else run.agent_by_name[name]

        def start(clause, time_s, _agent=agent, _name=name) -> None:
            run.events.append(Event(time_s, "trigger", {"actor": _name, "behavior": clause.name}))
            return run._start_behavior(_agent, clause, time_s)

        script.advance(t_now, holds, start, lambda beh, time_s, _agent=agent: run.behavior_ended(_agent, beh, time_s))
        if script.done:
            del run.scripts[name]


def _advance_light_script(run: _Run, rec, k: int, t_now: float) -> None:
    holds = _condition_checker(run, rec, k)

    def start(clause, time_s) -> None:
        run.events.append(Event(time_s, "trigger", {"light": clause.name, "state": clause.settings["state"]}))
        run.lights.change(clause.name, time_s, clause.settings["state"])

    run.light_script.advance(t_now, holds, start)
    if run.light_script.done:
        run.light_script = None


def oracles_signals(expr) -> set[str]:
    from addt_dsl.expr import signals_used

    return signals_used(expr)


def _snapshot_trace(run: _Run, rec, k: int, with_steps: bool = True) -> Trace:
    actors = {}
    sizes = {"ego": (run.ego_plan.length_m, run.ego_plan.width_m)}
    sizes.update({a.name: (a.length_m, a.width_m) for a in run.agents})
    frames = {"ego": run.ego_road.road_id}
    frames.update({a.name: run.agent_roads[a.name].road_id for a in run.agents})
    for name, r in rec.items():
        actors[name] = ActorTrack(name, *sizes[name], **{f: v[k:k + 1] for f, v in r.items()}, frame=frames[name])
    lat = {n: np.array([v]) for n, v in run.stack.latency.items()}
    t = k * run.dt
    lights = {n: np.array([run.lights.state(n, t)]) for n in run.lights.programs} if run.lights else {}
    trace = Trace(run.dt, np.array([t]), actors, lat, lights=lights)
    if run.named_steps and with_steps:  # `when ended(lead.brake_hard)` reads the states now
        trace.steps = {name: np.array([code], dtype=np.int8) for name, code in run.step_states(t).items()}
    return trace


def judge(bound: BoundScenario, trace: Trace) -> list[Verdict]:
    """Evaluate every oracle of the bound scenario on a trace (robustness at time 0)."""
    out = []
    for o in bound.oracles:
        formula = o.formula
        signals = compute_signals(trace, oracles_signals(formula))
        rho = float(oracles.robustness_at_0(formula, signals, trace.period_s))
        passed = oracles.satisfied(formula, signals, trace.period_s)
        first = None if passed else oracles.first_violation_time(formula, signals, trace.period_s)
        out.append(Verdict(o.name, o.severity, rho, passed, first))
    return out
