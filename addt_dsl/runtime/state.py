"""The state of one run (`RunState`): the bound plan, the ego and agents with their roads,
behaviours and scripts, lights, sensors, the stack and its queues, the physics world;
and its implementations of the declared interfaces (`views`): the world views that
behaviours and sensors read (`RunState`) and the stack's context (`Context`)."""

from __future__ import annotations

import dataclasses
import math
import re
import zlib

import numpy as np

from addt_dsl.plan import RunSpec
from addt_dsl.registry import BEHAVIORS, ENVIRONMENTS, SENSORS, STACKS
from addt_dsl.runtime.actor_road import ActorPath, ActorRoad, PlainLeg, junction_legs
from addt_dsl.runtime.agents import Fleet
from addt_dsl.runtime.behaviors import AgentState, advance
from addt_dsl.runtime.bound import BoundActor, BoundClause, BoundScenario, bind
from addt_dsl.runtime.environment import friction_scale
from addt_dsl.runtime.faults import FaultSchedule
from addt_dsl.runtime.lights import LightsRuntime, Program, StopStation, next_stop, stations_on, stop_accel, stop_lines
from addt_dsl.runtime.neighbours import LeaderIndex, Member, leader_scan
from addt_dsl.runtime.path import RoutePath
from addt_dsl.road import resolve_route
from addt_dsl.runtime.roadmesh import build_scene
from addt_dsl.road.roadspec import build_network
from addt_dsl.runtime.script import Script
from addt_dsl.runtime.signs import SignsRuntime, junction_rule, next_sign, sign_lines, stop_sign_lines
from addt_dsl.runtime.signals import STEP_ENDED, STEP_STARTED, STEP_WAITING
from addt_dsl.runtime.trace import Event
from addt_dsl.runtime.vehicle import HEADING, PITCH, VX, VY, X, Y, VehicleParams, VehicleState
from addt_dsl.runtime.triggers import Conditions
from addt_dsl.runtime.world import PhysicsWorld
from addt_dsl.vehicles import VEHICLES


LANE_SETTINGS = ("to", "lane")  # behaviour settings that name a lane id


def _is_live(clause: BoundClause) -> bool:
    """Whether a behaviour has a setting that reads signals (kept as an expression)."""
    return any(not isinstance(v, (int, float, str, list)) for v in clause.settings.values())


def _stable_seed(*parts) -> list[int]:
    return [int(p) if isinstance(p, int) else zlib.crc32(str(p).encode()) for p in parts]


class Context:
    """What the stack may see and do (`views.HostContext`): its sensors, the map, the fault
    schedule, the clock."""

    def __init__(self, run: RunState):
        self._run = run
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

    def stop_sign_ahead(self, s: float, stopped: tuple[float, ...] = ()) -> float | None:
        """Station [m] on the ego's road or route of the next stop sign's line ahead of the
        ego's front at station `s`, other than the lines in `stopped`, or None: the map as a
        connected vehicle would know it."""
        run = self._run
        if run.signs is None:
            return None
        return next_sign([st.u for st in run.sign_stations["ego"]], s + 0.5 * run.ego_plan.length_m, stopped)

    def junction_rule(self, s: float) -> str | None:
        """The right-of-way rule of the ego's approach to the next junction on its route
        (`signs.RULES`: "stop", "yield", "priority"), or None: no sign of the map (nor a
        priority road)."""
        run = self._run
        return junction_rule(run.rule_stations, run.ego_junctions, s + 0.5 * run.ego_plan.length_m)

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

    def ego_signs(self):
        """(kind, x, y, z, heading of the ego's lane) where each sign's line on the ego's road
        or route meets the ego's lane, in route order (`signs.SIGN_KINDS`)."""
        run = self._run
        road, out = run.ego_road, []
        for st in run.rule_stations:
            x, y, h = road.pose(st.u, float(road.road.lane_center_t(run.ego_lane, st.u)))
            out.append((st.controller, x, y, road.elevation.at(st.u)[0], h))
        return out

    def light_state(self, controller: str, time_s: float) -> int:
        return self._run.lights.state(controller, time_s)

    def ego_light_stations(self) -> list[tuple[float, str]]:
        """(station [m] on the ego's road or route, controller) of each traffic light's stop
        line, in path order: what `stop_line_ahead` reads (the bridge sends them)."""
        return [(st.u, st.controller) for st in self._run.stop_stations.get("ego", ())]

    def ego_sign_stations(self) -> list[tuple[float, str]]:
        """(station [m] on the ego's road or route, kind) of each sign's line (`signs.SIGN_KINDS`),
        in path order: what `stop_sign_ahead` (the stop signs) and
        `junction_rule` read (the bridge sends them)."""
        return [(st.u, st.controller) for st in self._run.rule_stations]

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


class RunState:
    def __init__(self, spec: RunSpec, roads: dict | None = None):
        """`roads`: road networks and their sampled views by road plans, shared by the runs
        of a batch (`batch.execute_batch`): runs of equal road plans read the same roads
        (read-only, the views' caches fill alike whichever run asks), and the agents' phase
        poses all their agents on one road at once (`agents.Fleets`)."""
        self.spec = spec
        self.bound = plan = bind(spec)  # every parameter expression evaluated here, once
        self.dt = plan.step_s
        self.n_steps = int(round(plan.duration_s / self.dt))
        self.events: list[Event] = []
        self.left_road = False  # the ego passed the end of its road or route (`left_road` event)
        # Actors whose `road_edge` a condition or an oracle reads: recorded for them only.
        plan_json = spec.plan.model_dump_json()  # (formulas read as text: one dump for the five searches)
        self.edge_actors = sorted(set(re.findall(r"road_edge\((\w+)\)", plan_json)))
        self.edges: dict = {}  # their recorded arrays (`phases.Record`)
        self.end_actors = sorted(set(re.findall(r"road_end\((\w+)\)", plan_json)))  # `road_end`
        self.ends: dict = {}
        # `wrong_way(A)`, `off_lanes(A)` (`lanestate.py`): recorded for the actors a formula reads
        self.wrong_way_actors = sorted(set(re.findall(r"wrong_way\((\w+)\)", plan_json)))
        self.off_lanes_actors = sorted(set(re.findall(r"off_lanes\((\w+)\)", plan_json)))
        # Whether a formula (the plan's or a fault's window) reads `lane_id(A)`: then lanes are
        # recorded per sample.
        self.lane_ids = '"lane_id(' in plan_json or any('"lane_id(' in f.model_dump_json() for f in spec.faults)
        self.wrong_ways: dict = {}
        self.offs: dict = {}
        self.red_margins: dict = {}  # each actor's recorded `red_light` margin (`phases.Record`)
        self.sign_margins: dict = {}  # and `stop_sign` margin
        key = tuple(rp.model_dump_json() for rp in plan.roads)
        shared = None if roads is None else roads.get(key)
        if shared is None:
            shared = (build_network(plan.roads), {})  # (networks, their roads' sampled views)
            if roads is not None:
                roads[key] = shared
        self.networks, self._road_cache = shared
        self._lanes_moving: dict = {}  # (id(road), lane) -> whether its centre t varies (`follow_lane`)
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
        self.conditions = Conditions(self)  # what trigger conditions and live settings read
        self.behavior_version = 0  # behaviours started so far
        self.released: set[str] = set()  # actors whose completed speed behaviour let go (`move`)

        ego = plan.ego
        self.ego_plan = ego
        self.ego_road = self._road_of(ego)
        s0, direction = self.ego_road.placement(self._first_road(ego), ego.s)
        # On a path lane ids are in driving convention (road id x direction), the direction
        # the declared road's leg's (at its end the path's station is the next leg's start).
        self.ego_lane = ego.lane * direction
        t0 = float(self.ego_road.road.lane_center_t(self.ego_lane, s0)) + ego.offset
        x, y, h = self.ego_road.pose(s0, t0)
        if ego.yaw:
            h += ego.yaw
        self.vehicle_params = VehicleParams.for_vehicle(ego.mass_kg, ego.wheelbase_m, ego.mu)
        self.ego_mu = ego.mu  # the declared friction; `environment { road friction F }` scales it
        self.ego = VehicleState(x, y, h, ego.speed)
        self.ego_row = 0  # the ego's row in its batch's block of ego states (`batch._loop`, `vehicle.StateBlock`)
        self.ego_z, self.ego.pitch = 0.0, 0.0
        self.ego_s, self.ego_t = s0, t0
        self.ego_offset: float | None = None  # [m] the lane offset at (ego_s, ego_t) where `phases.pose` found it
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
            u, direction = road.placement(self._first_road(a), a.s)
            lane = a.lane * direction
            t = float(road.road.lane_center_t(lane, u)) + a.offset
            st = AgentState(a.name, road.road_id, u, t, a.speed, 0.0, a.length_m, a.width_m, lane, t)
            self.agents.append(st)
            self._script(st, a, road)
        self.physics.add_boxes([(a.name, a.length_m, a.width_m, a.height_m, VEHICLES[a.vehicle].rgba)
                                for a in plan.agents])
        self.agent_by_name = {a.name: a for a in self.agents}
        # Members in `occupants` order (agents, then the ego): the order breaks leader ties.
        self.leaders = LeaderIndex([*self.agents, _EgoOccupant(self)])
        # Any actor on a path: agents find their leader by position (across roads), not by road.
        self.networked = isinstance(self.ego_road, ActorPath) or any(
            isinstance(r, ActorPath) for r in self.agent_roads.values())
        self.world_pose: dict[str, tuple[float, float, float]] = {}
        self.fleet = Fleet(self)
        self.contacts: set[tuple[str, str]] = set()  # actor pairs overlapping at the last step
        self.leaders_stale = False  # the leader index missed an array step: rebuilt before it is asked
        self.ego_grade = 0.0  # the road's grade along the ego's heading at its pose [-]
        self.status, self.error = "ok", ""  # "detected" and why, when the run stopped on a failure

        self.sensors = {}
        self.sensor_next: dict[str, float] = {}
        for clause in ego.sensors:
            cls = SENSORS.implementation(clause.name)
            sensor = cls(clause.name, clause.settings)
            self.sensors[clause.name] = sensor
            self.sensor_next[clause.name] = 0.0
        self.environment = [ENVIRONMENTS.implementation(c.name)(c.settings) for c in plan.environment]
        # Changes of the conditions during the run (`at 10 s fog visibility 20 m`).
        self.environment_script = Script(plan.environment_steps) if plan.environment_steps else None
        self.apply_friction()
        self.inflight: list[tuple[float, int, object]] = []  # frames in transit to the stack
        self._frame_seq = 0
        self._setup_lights(plan)
        self._setup_signs(plan)
        # Scenario variables now, and the steps that set them (`at 3 s set phase 1`).
        self.variables = dict(plan.variables)
        self.variable_script = Script(plan.variable_steps) if plan.variable_steps else None
        self.variable_records: dict = {}  # their recorded arrays (`phases.Record`)
        # `end when ...`: a start without a behaviour; the run ends where it fires.
        self.end_script = Script((plan.end,)) if plan.end is not None else None
        self.ego_junctions = junction_legs(self.ego_road)
        self.ctx = Context(self)
        stack_clause = ego.stack
        if stack_clause is None:  # a scripted ego without a stack
            self.stack = _NoStack()
        else:
            self.stack = STACKS.implementation(stack_clause.name)(stack_clause.settings, self.ctx)
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
        stop_at_end = self.agent_plans[a.name].stop_at_road_end
        # `at_road_end stop`: held at its road's end; as esmini, its speed drops to 0 in the step
        # after it arrived (one teleported away from the end at once keeps its speed), and a
        # speed behaviour that had completed lets go: the actor stands until another starts.
        at_end = stop_at_end and a.s >= self.agent_roads[a.name].road.length
        if at_end and beh is not None and a.name not in self.released and beh.ended(a, self, t_now):
            self.released.add(a.name)
        accel = beh.accel(a, self, t_now) if beh is not None and a.name not in self.released else 0.0
        if self.lights is not None and not a.heading_rel and not self.agent_plans[a.name].ignore_lights:
            accel = self.stop_for_lights(a, accel, t_now)
        advance(a, accel, t_now, dt)
        if a.lane_anchor is not None:
            self.follow_lane(a)
        if stop_at_end:
            end = self.agent_roads[a.name].road.length
            if a.s >= end:
                a.s = end
                if at_end:
                    a.speed, a.accel = 0.0, 0.0

    def follow_lane(self, a: AgentState) -> None:
        """Keep an agent that changed lanes on its lane where the lane's centre moves in its
        road's frame: esmini's entities keep their lane and offset, so one that changed into
        road 0's lane -2 stays there while the route's reference (the ramp lane it left)
        narrows and crosses over. Set by a lane change into a lane that moves (`lane_moves`);
        held on the leg's road of the change, dropped on another road or once it walks."""
        lane, leg, c_last = a.lane_anchor
        road = next(r for r in self.agent_roads.values() if r.road_id == a.road).road
        leg_now = road.road_at(a.s)[0] if isinstance(road, RoutePath) else a.road
        if a.heading_rel or (leg is not None and leg_now != leg):
            a.lane_anchor = None
            return
        c = float(road.lane_center_t(lane, a.s))
        if not math.isfinite(c):
            a.lane_anchor = None
            return
        d = c - c_last
        if a.lc_centre is not None:  # the change itself follows the moving centre (`lateral_profile`)
            d = 0.0
        if d:
            a.t += d
            a.t_target += d
            a.t_start += d
        a.lane_anchor = (lane, leg_now, c)

    def lane_moves(self, road_id: str, lane: int) -> bool:
        """Whether `lane`'s centre t varies along the road or route (its samples); cached."""
        road = next(r for r in self.agent_roads.values() if r.road_id == road_id).road
        key = (id(road), lane)
        got = self._lanes_moving.get(key)
        if got is None:
            c = np.array([road.lane_center_t(lane, u) for u in road._s], dtype=float)
            c = c[np.isfinite(c)]
            got = self._lanes_moving[key] = bool(c.size) and float(np.ptp(c)) > 1e-9
        return got

    def apply_friction(self) -> None:
        """The ego's tyre-road friction under the current conditions (`road friction F`)."""
        mu = self.ego_mu * friction_scale(self.environment)
        if mu != self.vehicle_params.mu:
            self.vehicle_params = dataclasses.replace(self.vehicle_params, mu=mu)

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

    def _setup_signs(self, plan: BoundScenario) -> None:
        """Stop signs: the lines of each map's stop signs, and where each actor meets them
        along its road or route (none: `self.signs` is None)."""
        self.signs: SignsRuntime | None = None
        self.sign_stations: dict[str, list[StopStation]] = {}
        self.rule_stations: list[StopStation] = []  # the ego's, `controller` the sign's kind
        by_map: dict[int, tuple] = {}  # one scan per network object (roads of one map may share it)
        lines: dict[str, list] = {}
        rules: dict[str, list] = {}  # every sign kind's lines, for the ego's junction rules
        for r in plan.roads:
            if r.source == "xodr":
                network = self.networks[r.name]
                if id(network) not in by_map:
                    by_map[id(network)] = (stop_sign_lines(network), sign_lines(network))
                lines[r.name], rules[r.name] = by_map[id(network)]
        self.rule_stations = self._stations(self.ego_road, plan.ego, rules.get(plan.ego.road, []))
        stations = {"ego": self._stations(self.ego_road, plan.ego, lines.get(plan.ego.road, []))}
        for a in plan.agents:
            stations[a.name] = self._stations(self.agent_roads[a.name], a, lines.get(a.road, []))
        if any(stations.values()):
            self.signs, self.sign_stations = SignsRuntime(), stations

    @staticmethod
    def _stations(road: ActorRoad, actor: BoundActor, lines) -> list[StopStation]:
        if not lines:
            return []
        if isinstance(road, ActorPath):
            return stations_on(lines, road.road.legs, road.station)
        plain = PlainLeg(road.road_id, 1, 0.0, float(road.network.road(road.road_id).length), actor.lane)
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
        if rp.source == "xodr" and rp.xodr_road_id:
            return rp.xodr_road_id
        return next(iter(self.networks[actor.road].roads))

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
        v = self.ego.row.tolist()  # (one read of its row: cheaper than four attributes)
        return v[X], v[Y], v[HEADING], math.hypot(v[VX], v[VY])

    def ego_frame(self):
        """(x, y, z of the road under the ego, heading, pitch nose-up) for sensor mounts."""
        v = self.ego.row.tolist()
        return v[X], v[Y], self.ego_z, v[HEADING], v[PITCH]

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

    def lane_number(self, name: str) -> float:
        """`actor_lane` as a number: NaN off the lanes (the ego past its road's end too)."""
        lane = None if name == "ego" and self.left_road else self.actor_lane(name)
        return math.nan if lane is None else float(lane)

    def road_band_t(self, road_id: str, s: float) -> tuple[float, float]:
        road = next(r for r in self.agent_roads.values() if r.road_id == road_id)
        return road.road.road_band_t(s)

    def ray_cast(self, starts, ends):
        return self.physics.ray_cast(starts, ends, ignore="ego")

    def ray_scene(self):
        return self.physics.ray_scene(ignore="ego")

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
        return self.conditions.live_value(expr, *self.recorded)

    def _start_behavior(self, agent: AgentState, clause: BoundClause, time_s: float):
        cls = BEHAVIORS.implementation(clause.name)
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
            self.released.discard(agent.name)
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
            out[name] = STEP_ENDED if ended else STEP_STARTED if step.started else STEP_WAITING
        return out


class _Projected:
    """An actor projected onto another's path (`RunState._leader_by_position`): its speed
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

    def __init__(self, run: RunState):
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
