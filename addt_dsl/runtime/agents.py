"""The agents: how actors are posed on their roads (`pose_on_road`, the one way: agents one
by one or as arrays, the scripted ego), one run's agents (`Fleet`: poses, rows, ground
truth), and the agents' phases over a batch (`Fleets`: the poses as one numpy program and
the longitudinal step of agents whose behaviours have an array law (IDM, cruise, brake) as
one compiled kernel, `fleet.step`, over every live run's agents, read from and written to
the batch's `agent_arrays.AgentArrays` block; a single run is a batch of one)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from addt_dsl.kernel import kernel
from addt_dsl.runtime import fleet
from addt_dsl.runtime.actor_road import ActorPath
from addt_dsl.runtime.agent_arrays import ACCEL, SCALE, SPEED, AgentArrays, S, T
from addt_dsl.runtime.behaviors import (LATER, LAW_NONE, lateral_profile, relative_heading, settle_lane_change,
                                        standing_yaw)
from addt_dsl.runtime.fastroad import POSE_GRADE, POSE_H, POSE_OFFSET, POSE_X, POSE_Y, POSE_Z
from addt_dsl.runtime.neighbours import LANE_WINDOW_M


def pose_on_road(a, road, yaw: float, t_now: float, dt: float, s: float, t: float) \
        -> tuple[float, float, float, float, float]:
    """(x, y, road heading, body heading, ground scale) of an actor on its road or path at its
    (s, t): the road's heading plus a lane change's or walk's relative heading and, while it
    has stood still, its declared yaw [rad]; its ground scale, which its caller keeps (its
    station moves by speed / ground_scale). Every actor posed one by one is posed here
    (`Fleets.pose` is the same over arrays)."""
    x, y, h = road.point(s, t)
    heading = h + relative_heading(a, t_now, dt)
    if yaw:
        heading += standing_yaw(a, yaw)
    return x, y, h, heading, road.ground_scale(s, t)


# Agents posed as arrays from this many on in a batch (all its runs' together): with one,
# the per-agent code is quicker (the pose and record phases of a 1-agent run-step measured
# ~14-18 us one by one against ~20 as arrays; with 2 and 3 agents the arrays were quicker,
# 17-19 us against 21-30: benchmarks/bench_pose.py --pose-min, bench_phases.py). Both ways
# give the same bits. (The step goes through its kernel whatever the count: `Fleets.step`.)
ARRAY_MIN_AGENTS = 2


class Fleet:
    """One run's agents for the loop: what does not change over the run (their roads,
    sizes, physics slots, array plan), the poses of the step (arrays, or lists of floats when
    posed one by one), the recorded rows and perception's ground truth. The array
    programs over the agents of every run of a batch are `Fleets.pose` and `Fleets.step`;
    a single run is a batch of one.

    The agents' numbers live in a block of arrays (`AgentArrays`: run `run_row`'s slots
    `block_rows`); the `AgentState` objects are views of it for the code that reads or moves
    one agent (behaviours, scripts, oracles, the per-agent step)."""

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
        self.groups = [(fast, elev, np.array(rows, dtype=np.intp)) for fast, elev, rows in groups.values()]
        plans = [run.agent_plans[a.name] for a in agents]
        self.yaws = [p.yaw for p in plans]
        self.yaw = [(i, p.yaw) for i, p in enumerate(plans) if p.yaw]
        self.half_height_m = [p.height_m / 2 for p in plans]
        self.half_height = np.array(self.half_height_m)
        self.kinds = [p.vehicle for p in plans]
        self.length = np.array([a.length_m for a in agents])
        self.slots = np.array(run.physics.box_slots([a.name for a in agents]), dtype=np.intp)
        codes: dict[str, int] = {}
        road_code = np.array([codes.setdefault(a.road, len(codes)) for a in agents], dtype=np.int64)
        # Who sees whom (`fleet.step`): lengths, road codes, the ego's length and road code.
        ego_code = codes.setdefault(run.ego_road.road_id, len(codes))
        self.members = (self.length, road_code, run.ego_plan.length_m, ego_code)
        self.posed = False
        self.x, self.y, self.heading = [], [], []
        self.rows = [] if n == 0 else None  # the agents' row fields as lists of floats, when posed one by one
        # Posed as arrays (`rows` None): `Fleets._pose_arrays`' table (x, y, body heading,
        # speed, lane offset, ... x the batch's agents) and this run's first column.
        self.pose, self.pose_lo = None, 0
        self._plan_version = -1
        self._plan = None
        self.bind(AgentArrays.adopt([agents]), 0)  # a block of one run, until a batch adopts them

    binds = 0  # `bind` calls so far, of every fleet (a `_Layout` made since holds while none)

    def bind(self, block: AgentArrays, run: int) -> None:
        """The agents are run `run` of `block` now (they were moved there: `AgentArrays.adopt`)."""
        self.block, self.run_row, self.block_rows = block, run, block.rows(run)
        Fleet.binds += 1

    def pose_one_by_one(self, run, t_now: float, dt: float) -> None:
        """The per-agent code (`pose_on_road`, the same formulas as `Fleets.pose`): poses,
        and the rows as lists of floats."""
        set_pose = run.physics.set_pose
        x, y, heading, rows, scale = [], [], [], [], []
        state = self.block.values[:, self.run_row, :self.n]  # (the run's block, read once)
        s_, t_, v, accel = state[:ACCEL + 1].tolist()
        for a, road, yaw, half_height, s, t, vi, ai in zip(self.agents, self.roads, self.yaws, self.half_height_m,
                                                           s_, t_, v, accel):
            xi, yi, h, hi, g = pose_on_road(a, road.road, yaw, t_now, dt, s, t)
            z, grade = road.elevation.at(s)
            off = road.road.lane_offset(s, t)
            set_pose(a.name, xi, yi, z + half_height, hi, math.atan(grade) * math.cos(hi - h))
            x.append(xi), y.append(yi), heading.append(hi), scale.append(g)
            rows.append((xi, yi, hi, vi, ai, 0.0, s, t, off, 0.0))
        state[SCALE] = scale
        self.x, self.y, self.heading, self.v, self.rows = x, y, heading, v, rows
        self.posed = True

    def road_pose(self, i: int):
        """(x, y, road heading, lane offset, z, grade) of agent i, one by one."""
        a, road = self.agents[i], self.roads[i]
        x, y, h = road.road.point(a.s, a.t)
        z, grade = road.elevation.at(a.s)
        return x, y, h, road.road.lane_offset(a.s, a.t), z, grade

    def record(self, block: np.ndarray, k: int) -> None:
        """The agents' fields of sample k's row of a run's record `block` (actors 1.., fields
        `phases.FIELDS` but steer and the clearance; the yaw rate 0): posed as arrays, one
        kernel call (`_agent_rows`) from the poses and the agents' block."""
        if self.rows is not None:
            block[k, 1:, :-1] = self.rows
            return
        _agent_rows(block, k, self.pose, self.pose_lo, self.block.flat, self.block_rows)

    def ground_truth(self, name: str | None):
        """An agent as perception's ground truth sees it (pose of the step, speed then)."""
        i = self.index.get(name)
        if i is None or not self.posed:
            return None
        a = self.agents[i]
        if self.rows is None:  # posed as arrays: their table's column
            pose, k = self.pose, self.pose_lo + i
            return _GT(float(pose[POSE_X, k]), float(pose[POSE_Y, k]), float(pose[_HEADING, k]),
                       float(pose[_SPEED, k]), a.length_m, a.width_m, self.kinds[i])
        return _GT(float(self.x[i]), float(self.y[i]), float(self.heading[i]), float(self.v[i]),
                   a.length_m, a.width_m, self.kinds[i])

    def poses(self) -> tuple:
        """The agents' (x, y, body heading) of the step, as sequences."""
        if self.rows is None:
            lo = self.pose_lo
            return tuple(self.pose[(POSE_X, POSE_Y, _HEADING), lo:lo + self.n])
        return self.x, self.y, self.heading

    def array_plan(self, run, t_now: float):
        """(law settings (`fleet.law_params`: `LAW_PARAMS` x agents), each agent's law
        (`behaviors.LAWS`), rows in a lane change, lateral targets) when every agent can be
        stepped by the kernel from the step at `t_now` [s] on (`Fleets.step`: each
        longitudinal behaviour has an array law, `Behavior.array_law`), else None. Kept
        until a behaviour starts (`RunState.behavior_version`: a `when ... then behavior`
        switches an agent's law), asked again at each step while one may become such a law
        later (a lane anchor held, a speed change under way)."""
        if run.behavior_version == self._plan_version:
            return self._plan
        if self.block.anchored[self.run_row]:
            return None  # one by one while `RunState.follow_lane` may move one (asked again next step)
        self._plan_version, self._plan = run.behavior_version, None
        if run.networked or run.lights is not None or not self.n:
            return None
        laws = []
        for a in self.agents:
            beh = run.longitudinal[a.name]
            if a.heading_rel or a.lc_keeps_station or run.agent_plans[a.name].stop_at_road_end:
                return None  # (the loop steps lane offsets' stations and stops at road ends)
            law = _NO_LAW if beh is None else beh.array_law(run, t_now)
            if law is None:
                return None
            if law is LATER:
                self._plan_version = -1  # (asked again at the next step)
                return None
            laws.append(law)
        changing = [i for i, a in enumerate(self.agents) if a.lc_duration_s > 0.0]
        target = np.array([a.t_target for a in self.agents], dtype=float)
        code, params = fleet.law_params(laws)
        self._plan = (params, code, changing, target)
        return self._plan


_NO_LAW = (LAW_NONE, ())  # an agent without a longitudinal behaviour: no acceleration


class _Layout:
    """The agents of some runs concatenated, run after run: run j's agents are rows
    lo[j]:lo[j + 1] of every array, read from and written to their block's slots `cells`
    (`AgentArrays.flat`); the rows of each road (roads shared by runs, as the batch's runs
    share their roads' sampled views, are one group), and who sees whom."""

    def __init__(self, fleets: list[Fleet]):
        self.fleets = fleets
        self.block = fleets[0].block
        if any(f.block is not self.block for f in fleets):  # runs not stepped as one batch yet
            self.block = AgentArrays.adopt([f.agents for f in fleets])
            for r, f in enumerate(fleets):
                f.bind(self.block, r)
        self.cells = np.concatenate([f.block_rows for f in fleets])
        sizes = [f.n for f in fleets]
        self.lo = np.cumsum([0, *sizes]).tolist()
        self.starts = np.array(self.lo[:-1], dtype=np.intp)  # (for `reduceat` per run)
        self.n = self.lo[-1]
        groups: dict[int, tuple] = {}
        self.path_rows = []
        self.yaw = []
        for f, lo in zip(fleets, self.lo):
            for fast, elev, rows in f.groups:
                groups.setdefault(id(fast), (fast, elev, []))[2].append(rows + lo)
            self.path_rows += [(lo + i, f, i) for i in f.path_rows]
            self.yaw += [(lo + i, f.agents[i], yaw) for i, yaw in f.yaw]
        self.groups = [(fast, elev, np.concatenate(parts)) for fast, elev, parts in groups.values()]
        self.yaw_rows = np.array([k for k, _, _ in self.yaw], dtype=np.intp)
        self.zeros = np.zeros(self.n)  # (no agent turned off its road's heading: never written)
        self.half_height = np.concatenate([f.half_height for f in fleets])
        self.length = np.concatenate([f.length for f in fleets])
        # `fleet.step`'s arguments that stay: run bounds, road codes, the egos' lengths and codes
        self.bounds = np.array(self.lo, dtype=np.int64)
        self.road = np.concatenate([f.members[1] for f in fleets]).astype(np.int64)
        self.ego_length = np.array([f.members[2] for f in fleets], dtype=float)
        self.ego_road = np.array([f.members[3] for f in fleets], dtype=np.int64)
        self.placed = self.block.placed.reshape(-1)  # (a view: teleports write it)
        self.done = np.empty(len(fleets), dtype=bool)
        self.dt = None  # the runs' steps [s], at the first step
        self._plans: list = []
        self._laws = None
        self.binds = Fleet.binds
        self.record_key: tuple | None = None  # `Fleets.record_columns`' runs, and its arrays
        self.record_args: tuple = ()

    def laws(self, plans):
        """The runs' law settings, each agent's law, the lateral targets, concatenated; the
        agents in a lane change (row, run, agent). Made again when a run's plan changed (a
        behaviour started)."""
        if len(plans) != len(self._plans) or any(p is not q for p, q in zip(plans, self._plans)):
            changing = [(lo + i, j, f.agents[i]) for j, (p, f, lo) in enumerate(zip(plans, self.fleets, self.lo))
                        for i in p[2]]
            self._laws = (np.concatenate([p[0] for p in plans], axis=1), np.concatenate([p[1] for p in plans]),
                          np.concatenate([p[3] for p in plans]), changing)
            self._plans = list(plans)
        return self._laws


class Fleets:
    """The agents' phases over a batch of runs: every run's agents at once (`pose`: numpy
    over runs x agents; `step`: the kernel `fleet.step`), with the floats of the per-agent
    code. Runs whose agents cannot go so (non-finite stations; for the step: networked runs,
    lights, behaviours without an array law, see `Fleet.array_plan`) and, for
    the poses, batches of few agents (the per-agent calls are quicker: `ARRAY_MIN_AGENTS`)
    go one by one inside the same phase.

    `runs`: the batch, whose agents move into one block (`AgentArrays`, a leading runs axis)."""

    def __init__(self, runs=()):
        self._layouts: dict[tuple[int, ...], _Layout] = {}
        self._last: _Layout | None = None  # the layout asked for last (the pose and step phases ask each step)
        self.posed: tuple | None = None  # (pose table, layout) of the last `pose`, all runs' agents as arrays
        if runs:
            block = AgentArrays.adopt([run.fleet.agents for run in runs])
            for r, run in enumerate(runs):
                run.fleet.bind(block, r)

    def _layout(self, fleets: list[Fleet]) -> _Layout:
        last = self._last
        if last is not None and last.binds == Fleet.binds and last.fleets == fleets:  # (list ==: by identity)
            return last
        key = tuple(map(id, fleets))
        layout = self._layouts.get(key)
        if layout is None or layout.binds != Fleet.binds or layout.fleets != fleets:
            layout = self._layouts[key] = _Layout(fleets)
            while len(self._layouts) > 4:  # live sets change as runs end: keep the recent ones
                del self._layouts[next(iter(self._layouts))]
        self._last = layout
        return layout

    def pose(self, runs, ts) -> None:
        """Pose every agent of the batch on its road (`road.point`, the relative heading of a
        lane change or a walk, the extra yaw, the elevation) and hand the poses to each run's
        physics world; keep them, and each agent's lane offset, for the row."""
        items = [(run, t) for run, t in zip(runs, ts) if run.fleet.n]
        self.posed = None
        if sum(run.fleet.n for run, _ in items) >= ARRAY_MIN_AGENTS:
            items = self._pose_arrays(items)
            if items:  # (some runs' agents posed one by one)
                self.posed = None
        for run, t in items:
            run.fleet.pose_one_by_one(run, t, run.dt)
        for run in runs:
            if run.networked:
                f = run.fleet
                for a, xi, yi, hi in zip(f.agents, *f.poses()):
                    run.world_pose[a.name] = (float(xi), float(yi), float(hi))

    def _pose_arrays(self, items):
        """`Fleet.pose_one_by_one` as arrays over the batch's agents, bit for bit: each road's
        agents in one kernel call (`FastRoad.pose_rows`: the scalar calls' code), the body
        headings and pitches in another (`_body_poses`). The runs left one by one
        (non-finite stations)."""
        if not items:
            return []
        layout = self._layout([run.fleet for run, _ in items])
        flat, cells = layout.block.flat, layout.cells
        n, lo = layout.n, layout.lo
        out = np.empty((_POSE_ROWS, n))
        finite = True
        for fast, elev, rows in layout.groups:
            if not fast.pose_rows(elev, flat, cells, rows, out):
                finite = False
                break
        if finite and layout.path_rows:
            finite = all(math.isfinite(f.agents[i].s) and math.isfinite(f.agents[i].t) for _, f, i in layout.path_rows)
        if not finite:
            s, t = flat[S:T + 1, cells]
            finite = np.logical_and.reduceat(np.isfinite(s) & np.isfinite(t), layout.starts).tolist()
            left = [item for item, ok in zip(items, finite) if not ok]
            return left + self._pose_arrays([item for item, ok in zip(items, finite) if ok])
        rel = None
        for j, (run, t_now) in enumerate(items):
            f = run.fleet
            plan = f.array_plan(run, t_now)  # with one, only lane changes turn agents off their road's heading
            lateral = plan[2] if plan is not None else \
                [i for i, a in enumerate(f.agents) if a.heading_rel or a.lc_duration_s > 0.0]
            for i in lateral:
                if rel is None:
                    rel = np.zeros(n)
                rel[lo[j] + i] = relative_heading(f.agents[i], t_now, run.dt)
        for k, f, i in layout.path_rows:  # routes: one by one
            a = f.agents[i]
            out[POSE_X, k], out[POSE_Y, k], out[POSE_H, k], out[POSE_OFFSET, k], out[POSE_Z, k], \
                out[POSE_GRADE, k] = f.road_pose(i)
            a.ground_scale = f.roads[i].road.ground_scale(a.s, a.t)
        yaw = np.array([standing_yaw(a, yaw) for _, a, yaw in layout.yaw], dtype=float) if layout.yaw else _NO_YAW
        _body_poses(out, layout.zeros if rel is None else rel, layout.yaw_rows, yaw, layout.half_height, flat, cells)
        for j, (run, _) in enumerate(items):  # (each run's poses: columns lo[j]: of `out`)
            f = run.fleet
            run.physics.set_poses(f.slots, out, lo[j], _BODY_COLUMNS)
            f.pose, f.pose_lo, f.rows, f.posed = out, lo[j], None, True
        self.posed = (out, layout)
        return []

    def record_columns(self, runs) -> tuple | None:
        """Where the last `pose` put the agents of `runs` (the runs it posed, in its order):
        (the pose table, the agents' block `AgentArrays.flat`, then per run its agents' count,
        its first column in the table and its first slot in the block: a run's agents' slots
        follow each other), or None where some run's agents were posed one by one
        (`Fleet.rows`)."""
        if self.posed is None:
            return None
        out, layout = self.posed
        key = tuple(map(id, runs))
        if layout.record_key != key:
            fleets = iter(zip(layout.fleets, layout.lo))
            counts, lo, cell0 = [], [], []
            for run in runs:
                n = run.fleet.n
                f, first = next(fleets) if n else (None, 0)
                if f is not None and f is not run.fleet:
                    return None  # (not the runs it posed)
                counts.append(n)
                lo.append(first)
                cell0.append(int(f.block_rows[0]) if n else 0)
            layout.record_key = key
            layout.record_args = tuple(np.array(v, dtype=np.int64) for v in (counts, lo, cell0))
        return (out, layout.block.flat, *layout.record_args)

    def step(self, runs, ts) -> list:
        """Advance every agent of the batch as the per-agent loop would (in each run's
        declaration order, each seeing the earlier ones moved): the runs whose agents all
        have an array plan (`Fleet.array_plan`) in one call of `fleet.step`, whatever their
        number; the (run, t) of the runs left to that loop."""
        items, rest = [], []
        for run, t in zip(runs, ts):
            (rest if run.fleet.array_plan(run, t) is None else items).append((run, t))
        return rest + self._step_arrays(items) if items else rest

    def _step_arrays(self, items) -> list:
        """`step` over runs whose agents all have an array plan: `fleet.step`; the runs it
        left (an agent teleported this step stays put, as `advance` has it; a non-finite
        station or offset)."""
        layout = self._layout([run.fleet for run, _ in items])
        plans = [run.fleet.array_plan(run, t) for run, t in items]
        params, law, target, changing = layout.laws(plans)
        t_new = target.copy() if changing else target  # (the kernel reads it)
        for k, j, a in changing:  # (reads the agent's station before it moves, as `advance`)
            run, t_now = items[j]
            t_new[k] = lateral_profile(a, t_now + run.dt)
        ego = np.array([x for run, _ in items for x in (run.ego_s, run.ego_t, run.ego.speed)], dtype=float)
        if layout.dt is None:
            layout.dt = np.array([run.dt for run, _ in items], dtype=float)
        left = fleet.step(layout.bounds, layout.cells, layout.block.flat, layout.placed, t_new, law, params,
                          layout.road, layout.length, ego, layout.ego_road, layout.ego_length, layout.dt,
                          LANE_WINDOW_M, layout.done)
        for k, j, a in changing:  # (only agents in a lane change may hold a moving centre)
            if a.lc_centre is not None and layout.done[j]:
                settle_lane_change(a, items[j][1] + items[j][0].dt, a.t)
        if not left:
            for run, _ in items:
                run.leaders_stale = True  # (the loop's index rebuilt before it is asked again)
            return []
        rest = []
        for item, ok in zip(items, layout.done.tolist()):
            if ok:
                item[0].leaders_stale = True
            else:
                rest.append(item)
        return rest


# `_pose_arrays`' rows: `FastRoad.pose_rows`' and the body's heading and pitch [rad], the speed [m/s].
_HEADING, _PITCH, _SPEED = 6, 7, 8
_POSE_ROWS = 9
_BODY_COLUMNS = np.array([POSE_X, POSE_Y, POSE_Z, _HEADING, _PITCH], dtype=np.int64)  # (`PhysicsWorld.set_poses`)
_NO_YAW = np.empty(0)


@kernel
def _body_poses(out, rel, yaw_rows, yaw, half_height, flat, cells):
    """Each agent's body heading (its road's plus `rel`, plus `yaw` at `yaw_rows`, in that
    order) and pitch (the grade's angle seen along the body: atan(grade) * cos(heading -
    road heading), 0 where flat and along the road), its centre's height (road z plus
    `half_height`), and its speed (block slot `cells[k]`), in `out`'s rows."""
    n = out.shape[1]
    for k in range(n):
        out[_HEADING, k] = out[POSE_H, k] + rel[k]
        out[_SPEED, k] = flat[SPEED, cells[k]]
    for j in range(yaw_rows.size):
        out[_HEADING, yaw_rows[j]] += yaw[j]
    for k in range(n):
        grade, heading, h = out[POSE_GRADE, k], out[_HEADING, k], out[POSE_H, k]
        out[_PITCH, k] = math.atan(grade) * math.cos(heading - h) if grade != 0.0 or heading != h else 0.0
        out[POSE_Z, k] += half_height[k]


@kernel
def _agent_rows(block, k, pose, lo, flat, cells):
    """Sample k's row of a run's record `block` for its agents (actor 1 + i) from their poses
    `pose[:, lo + i]` (`_pose_arrays`) and their block slots `cells[i]` (`agent_row`)."""
    for i in range(cells.size):
        agent_row(block[k, 1 + i], pose, lo + i, flat, cells[i])


@kernel
def agent_row(row, pose, j, flat, c):
    """An agent's recorded fields (columns x, y, heading, speed, accel, yaw rate 0, s, t, lane
    offset; `phases.FIELDS`) from its pose `pose[:, j]` and its block slot `c` (accel, s, t
    as posed: nothing moved since)."""
    row[0], row[1], row[2], row[3] = pose[POSE_X, j], pose[POSE_Y, j], pose[_HEADING, j], pose[_SPEED, j]
    row[4], row[5], row[6], row[7] = flat[ACCEL, c], 0.0, flat[S, c], flat[T, c]
    row[8] = pose[POSE_OFFSET, j]


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
    e.x, e.y, _, e.heading, a.ground_scale = pose_on_road(a, run.ego_road.road, run.ego_plan.yaw, t_now, dt,
                                                          a.s, a.t)
    e.vx, e.accel = a.speed, a.accel
    run.ego_s, run.ego_t = a.s, a.t
