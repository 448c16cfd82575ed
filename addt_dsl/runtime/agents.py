"""The agents: how actors are posed on their roads (`pose_on_road`, the one way: agents one
by one or as arrays, the scripted ego), and the agents as arrays (`Fleet`: poses, rows,
ground truth, and the longitudinal step of car-following agents over numpy arrays)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from addt_dsl.runtime import fleet
from addt_dsl.runtime.actor_road import ActorPath
from addt_dsl.runtime.behaviors import Idm, lateral_profile, relative_heading, settle_lane_change, standing_yaw
from addt_dsl.runtime.vehicle import VehicleState


def pose_on_road(a, road, yaw: float, t_now: float, dt: float) -> tuple[float, float, float, float]:
    """(x, y, road heading, body heading) of an actor on its road or path at its (s, t): the
    road's heading plus a lane change's or walk's relative heading and, while it has
    stood still, its declared yaw [rad]; keeps its ground scale (its station moves by
    speed / ground_scale). Every actor posed one by one is posed here (`Fleet._pose_arrays`
    is the same over arrays)."""
    x, y, h = road.point(a.s, a.t)
    a.ground_scale = road.ground_scale(a.s, a.t)
    heading = h + relative_heading(a, t_now, dt)
    if yaw:
        heading += standing_yaw(a, yaw)
    return x, y, h, heading


# Agents posed as arrays from this many on, and stepped as arrays from STEP_MIN_AGENTS on:
# fewer, and the per-agent code is quicker (posing: ~30 us of numpy calls against ~2 us
# per agent, measured break-even at ~24 agents; the array step asks two leader lookups of
# ~30 numpy calls each per step, a sorted-list bisect per agent costs ~2.5 us: measured
# break-even at 65-75 agents).
ARRAY_MIN_AGENTS = 24
STEP_MIN_AGENTS = 64


class Fleet:
    """The agents as arrays for the loop: each step's poses, road points and recorded
    rows computed for all agents at once (numpy over agents), and the longitudinal step
    of car-following agents (`step` below), with the floats of the per-agent code.

    The `AgentState` objects stay the agents' state (behaviours, scripts and oracles read
    them): a step gathers their stations, offsets and speeds into arrays and, when it
    steps them as arrays, writes the new values back."""

    def __init__(self, run):
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
        self._posed_version = -1
        self._plan_version = -1
        self._plan = None

    def gather(self) -> None:
        """Stations, offsets, speeds and accelerations of the agents now."""
        agents = self.agents
        self.s = np.array([a.s for a in agents], dtype=float)
        self.t = np.array([a.t for a in agents], dtype=float)
        self.v = np.array([a.speed for a in agents], dtype=float)

    def pose(self, run, t_now: float, dt: float) -> None:
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

    def _pose_one_by_one(self, run, t_now: float, dt: float) -> None:
        """The per-agent code: poses, and the rows as lists of floats."""
        set_pose = run.physics.set_pose
        x, y, heading, v, rows = [], [], [], [], []
        for a, road, yaw, half_height in zip(self.agents, self.roads, self.yaws, self.half_height_m):
            xi, yi, h, hi = pose_on_road(a, road.road, yaw, t_now, dt)
            z, grade = road.elevation.at(a.s)
            off = road.road.lane_offset(a.s, a.t)
            set_pose(a.name, xi, yi, z + half_height, hi, math.atan(grade) * math.cos(hi - h))
            x.append(xi), y.append(yi), heading.append(hi), v.append(a.speed)
            rows.append((xi, yi, hi, a.speed, a.accel, 0.0, a.s, a.t, off, 0.0))
        self.x, self.y, self.heading, self.v, self.rows = x, y, heading, v, rows

    def columns(self, ego: VehicleState):
        """(x, y, heading) of every actor, the ego first: lists or arrays as posed."""
        if self.rows is not None:
            return [ego.x, *self.x], [ego.y, *self.y], [ego.heading, *self.heading]
        return tuple(np.concatenate(([v], a))
                     for v, a in ((ego.x, self.x), (ego.y, self.y), (ego.heading, self.heading)))

    def _road_pose(self, i: int):
        """(x, y, road heading, lane offset, z, grade) of agent i, one by one."""
        a, road = self.agents[i], self.roads[i]
        x, y, h = road.road.point(a.s, a.t)
        z, grade = road.elevation.at(a.s)
        return x, y, h, road.road.lane_offset(a.s, a.t), z, grade

    def _pose_arrays(self, run, t_now: float, dt: float) -> None:
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
        i = self.index.get(name)
        if i is None or not self.posed:
            return None
        a = self.agents[i]
        return _GT(float(self.x[i]), float(self.y[i]), float(self.heading[i]), float(self.v[i]),
                   a.length_m, a.width_m, self.kinds[i])

    def _array_plan(self, run):
        """(IDM settings, their rows, rows in a lane change, lateral targets) when every
        agent can be stepped as arrays now, else None. Re-read when a behaviour starts."""
        if run.behavior_version == self._plan_version:
            return self._plan
        if any(a.lane_anchor is not None for a in self.agents):
            return None  # one by one while `RunState.follow_lane` may move one (asked again next step)
        self._plan_version, self._plan = run.behavior_version, None
        if run.networked or run.lights is not None or self.n < max(ARRAY_MIN_AGENTS, STEP_MIN_AGENTS):
            return None
        rows, settings = [], []
        for i, a in enumerate(self.agents):
            beh = run.longitudinal[a.name]
            if a.heading_rel or a.lc_keeps_station or run.agent_plans[a.name].stop_at_road_end:
                return None  # (the loop steps lane offsets' stations and stops at road ends)
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

    def step(self, run, t_now: float, dt: float) -> bool:
        """Advance every agent as the per-agent loop would (in declaration order, each
        seeing the earlier ones moved), as arrays; False (nothing changed) where the agents'
        behaviours or states leave it to that loop."""
        plan = self._array_plan(run)
        if plan is None:
            return False
        params, rows, changing, target = plan
        if any(a.placed for a in self.agents):
            return False  # (a teleported agent stays put this step: `advance`)
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
                    settle_lane_change(a, t_now + dt, ti)
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


@dataclass
class _GT:
    x: float
    y: float
    heading: float
    speed: float
    length_m: float
    width_m: float
    kind: str = ""  # the actor's vehicle kind (addt_dsl.vehicles)


def pose_scripted_ego(run, t_now: float, dt: float) -> None:
    """The scripted ego's vehicle state from its road-frame state, posed as an agent is."""
    a, e = run.ego_agent, run.ego
    e.x, e.y, _, e.heading = pose_on_road(a, run.ego_road.road, run.ego_plan.yaw, t_now, dt)
    e.vx, e.accel = a.speed, a.accel
    run.ego_s, run.ego_t = a.s, a.t
