"""One physics step of the twin as named phases over the run's state (`state.RunState`).

`batch._loop` runs them in this order at each sample k (time t = k * dt): the phases
that take the whole batch over every live run at once, the per-run phases between two of
them run by run (runs share nothing: each run sees its phases in this order):

  clock       the stack's clock; fault timers wake
  pose        agents on their roads (every run's agents at once: `agents.Fleets.pose`),
              the ego (projected onto its road: the batch's driven egos a kernel call per
              road; or posed from its script), their bodies in the physics world
  record      the state row of every actor (clearance, the last field, below; a batch's
              rows in one compiled call into its block, `Record.batch`); margins to red
              lights and stop signs; lane states (`lanestate.py`); the scenario variables
  collisions  each actor's clearance; `collision` events (`collision.py`: every live
              run's pairs in one compiled kernel over the batch's block)
  environment changes of the weather, light and road that fire on the recorded state
  variables   steps that set scenario variables, on the recorded state
  lights      light changes that fire on the recorded state; light states
  outputs     latencies, the command, objects seen, named steps' states
  end         `end when ...` on the recorded state
  -- the run stops here on an ego collision, its end, or its last sample --
  triggers    deferred time-0 behaviours; scripted steps (`triggers.py`); fault windows
              that a condition opens
  sense       due sensors capture, spatial and temporal faults act, frames travel
  stack       frames that arrived reach the stack, which steps
  ego         due commands take effect; the ego's dynamics (or its script, or an OSI stack)
  agents      every agent's longitudinal step (every run's agents at once as arrays where
              `agents.Fleets.step` can, else one by one)

Each phase reads and writes the run's state; `Record` holds the recorded arrays. The
phases that take the whole batch (`pose`, `record`, `collisions`, `ego`, `agents`) run
array programs over it (the egos' states are rows of one block, `vehicle.StateBlock`);
the others step per run.
"""

from __future__ import annotations

import heapq
import math
from itertools import accumulate

import numpy as np

from addt_dsl.kernel import kernel
from addt_dsl.runtime import lanestate
from addt_dsl.runtime.agents import Fleets, agent_row, pose_scripted_ego
from addt_dsl.runtime.collision import clearances_batch, clearances_rows
from addt_dsl.runtime.fastroad import FastRoad
from addt_dsl.runtime.signals import parse as parse_signal
from addt_dsl.runtime.state import LATENCY_NODES, RunState
from addt_dsl.runtime.trace import ActorTrack, Event, Trace
from addt_dsl.runtime.triggers import (advance_environment_script, advance_light_script, advance_scripts,
                                       advance_variable_script, condition_checker, prefetch)
from addt_dsl.runtime.vehicle import HEADING, X, Y, StateBlock, ego_record
from addt_dsl.specs.signals import FIELDS as SIGNAL_FIELDS

# The recorded fields of an actor, in the order of a step's row (the field signals'); clearance last.
FIELDS = tuple(name for name, _, _ in SIGNAL_FIELDS)
assert FIELDS[-1] == "clearance"
# Where the fields the ego's state gives go in its row (`vehicle.StateBlock.records`).
_EGO_COLUMNS = np.array([FIELDS.index(f) for f in ("x", "y", "heading", "speed", "accel", "yaw_rate", "steer")])
_S, _T, _LANE_OFFSET = FIELDS.index("s"), FIELDS.index("t"), FIELDS.index("lane_offset")


class Record:
    """The recorded arrays of a run, one row per sample: actors' fields (one block
    [sample, actor, field]: a step's state goes in as one row, per-value numpy stores cost
    ~0.1 us each), latencies, outputs, objects seen, named steps, lights. The records of a
    batch (`Record.batch`) keep their actors' fields in one block of the batch's."""

    def __init__(self, run: RunState, block: np.ndarray | None = None):
        n = self.n = run.n_steps + 1
        plan = run.bound
        names = self.names = ["ego"] + [a.name for a in run.agents]
        self.actor_index = {name: i for i, name in enumerate(names)}
        if block is None:
            block = np.zeros((n, len(names), len(FIELDS)))
        self.block = block
        self.batch_rows: BatchRows | None = None  # the batch's block this one is part of, and its index there
        self.index = 0
        self.rec = {name: dict(zip(FIELDS, fields)) for name, fields in zip(names, block.transpose(1, 2, 0))}
        self.latency = {k: np.zeros(n) for k in LATENCY_NODES}
        self.outputs = {"control.steer": np.zeros(n), "control.accel": np.zeros(n)}
        self.objects = np.zeros(n)
        self.steps = {name: np.zeros(n, dtype=np.int8) for _, name, _ in run.named_steps}
        self.lights = {c.name: np.zeros(n) for c in plan.controllers} if run.lights else {}
        self.margins = run.red_margins = {name: np.zeros(n) for name in names} if run.lights else {}
        self.sign_margins = run.sign_margins = {name: np.zeros(n) for name in names} if run.signs else {}
        self.lanes = {name: np.full(n, np.nan) for name in names} if run.lane_ids else {}
        self.edges = run.edges = {name: np.zeros(n) for name in run.edge_actors}  # (conditions read them)
        self.ends = run.ends = {name: np.zeros(n) for name in run.end_actors}
        self.wrong_ways = run.wrong_ways = {name: np.full(n, -1.0) for name in run.wrong_way_actors}
        self.offs = run.offs = {name: np.full(n, -1.0) for name in run.off_lanes_actors}
        self.variables = run.variable_records = {name: np.zeros(n) for name in run.variables}
        self.sizes = {"ego": (plan.ego.length_m, plan.ego.width_m)}
        self.sizes.update({a.name: (a.length_m, a.width_m) for a in run.agents})
        self.footprints = np.array([self.sizes[m] for m in names], dtype=np.float64).reshape(-1, 2)  # (length, width)
        # Whether the run records more than its actors' fields (`_record_extras`).
        self.extras = bool(self.lanes or self.edges or self.ends or self.wrong_ways or self.offs or self.variables
                           or run.lights is not None or run.signs is not None)
        self.last = n  # samples recorded

    @classmethod
    def batch(cls, runs: list[RunState]) -> list[Record]:
        """The records of a batch's runs, the fields of all their actors in one block
        [sample, actor of the batch, field] (`BatchRows`; each record's `block` the view of its
        run's actors and samples): a step's rows of every run are one array."""
        if len(runs) < 2:
            return [cls(run) for run in runs]
        first = [0, *accumulate(1 + len(run.agents) for run in runs)]
        block = np.zeros((max(run.n_steps for run in runs) + 1, first[-1], len(FIELDS)))
        recs = [cls(run, block[:run.n_steps + 1, lo:hi]) for run, lo, hi in zip(runs, first, first[1:])]
        rows = BatchRows(block, np.array(first, dtype=np.int64), np.concatenate([rec.footprints for rec in recs]))
        for i, rec in enumerate(recs):
            rec.batch_rows, rec.index = rows, i
        return recs

    def trace(self, run: RunState) -> Trace:
        last = self.last
        frames = {"ego": run.ego_road.road_id}
        frames.update({a.name: run.agent_roads[a.name].road_id for a in run.agents})
        actors = {}
        columns = np.ascontiguousarray(self.block[:last].transpose(1, 2, 0))  # [actor, field, sample]: one copy
        for i, name in enumerate(self.names):
            length, width = self.sizes[name]
            actors[name] = ActorTrack(name, length, width, **dict(zip(FIELDS, columns[i])), frame=frames[name])
        cut = lambda d: {k: v[:last] for k, v in d.items()}  # noqa: E731
        return Trace(run.dt, np.arange(last) * run.dt, actors, cut(self.latency), run.events, cut(self.outputs),
                     self.objects[:last], run.status, run.error, steps=cut(self.steps), lights=cut(self.lights),
                     red_margin=cut(self.margins), stop_margin=cut(self.sign_margins), lanes=cut(self.lanes),
                     road_edge=cut(self.edges),
                     road_end=cut(self.ends), variables=cut(self.variables), wrong_way=cut(self.wrong_ways),
                     off_lanes=cut(self.offs))


def clock(runs: list[RunState], ts: list[float]) -> None:
    """Over the batch: each run's clock; fault timers due wake (tensor hooks attach at their
    instants)."""
    for run, t in zip(runs, ts):
        run.ctx.now = t
        if t + 1e-12 >= run.faults.next_wake_s:
            run.faults.wake(t)


_FIELD_INDEX = {name: i for i, name in enumerate(FIELDS)}


class BatchRows:
    """The recorded fields of every actor of a batch: `block` [sample, actor, field], run r's
    actors `first[r]` to `first[r + 1]`, their footprints (length, width [m]) `sizes`; the
    block holds the batch's longest run (a shorter run's samples after its last stay 0)."""

    def __init__(self, block: np.ndarray, first: np.ndarray, sizes: np.ndarray):
        self.block, self.first, self.sizes = block, first, sizes
        self.first.flags.writeable = False
        self._live: list[int] = []
        self._live_a = np.zeros(0, dtype=np.int64)

    @staticmethod
    def of(recs: list[Record]) -> tuple[BatchRows, np.ndarray] | None:
        """The block several records are all part of and their runs' indices there (an array:
        the last one asked, the live runs, changes seldom), or None (one record, or records
        of other blocks)."""
        rows = recs[0].batch_rows if len(recs) > 1 else None
        if rows is None or any(rec.batch_rows is not rows for rec in recs):
            return None
        index = [rec.index for rec in recs]
        if index != rows._live:
            rows._live, rows._live_a = index, np.array(index, dtype=np.int64)
        return rows, rows._live_a

    def field_values(self, k: int, recs: list[Record], signals) -> dict[str, np.ndarray] | None:
        """The field signals `signals` (`speed(ego)`, `s(lead)`: an actor's recorded field,
        `signals.compute_signals`' names) at sample k of each of `recs`, in their order: what
        each run's one-sample snapshot gives, read from the block at once. None where one is
        not a field signal, a record is not of this block or a run has no such actor."""
        if any(rec.batch_rows is not self for rec in recs):
            return None
        out = {}
        for name in signals:
            fn, args = parse_signal(name)
            if fn not in _FIELD_INDEX or not args:
                return None
            cols = []
            for rec in recs:
                i = rec.actor_index.get(args[0])
                if i is None:
                    return None
                cols.append(self.first[rec.index] + i)
            out[name] = self.block[k, cols, _FIELD_INDEX[fn]]
        return out


def pose(runs: list[RunState], ts: list[float], fleets: Fleets, egos: StateBlock | None = None) -> None:
    """Over the batch: agents kinematic along their roads (every run's at once,
    `agents.Fleets.pose`), each ego where its dynamics or script put it (driven egos on a
    plain road, their rows in `egos`, projected onto it a kernel call per road:
    `FastRoad.ego_poses`); the bodies in the physics world (for perception) and the ego's
    road height and grade."""
    fleets.pose(runs, ts)
    posed = _ego_poses(runs, egos) if egos is not None and len(runs) > 1 else None
    if posed is None:
        for run, t in zip(runs, ts):
            _pose_ego(run, t, None)
    else:
        for run, t, pre in zip(runs, ts, posed):
            _pose_ego(run, t, pre)


def _ego_poses(runs: list[RunState], egos: StateBlock) -> list[list[float] | None]:
    """(x, y, heading, s, t, lane offset, z, grade) of each driven ego on a plain road
    (`FastRoad.ego_poses`, one call per road), None for the others (a script, a route, a
    road whose stations are not finite: posed one by one)."""
    posed: list[list[float] | None] = [None] * len(runs)
    groups: dict[int, list[int]] = {}
    for i, run in enumerate(runs):
        if run.ego_agent is None and type(run.ego_road.road) is FastRoad:
            groups.setdefault(id(run.ego_road.road), []).append(i)  # (a batch's runs share their roads)
    for members in groups.values():
        ego_road = runs[members[0]].ego_road
        rows = np.array([runs[i].ego_row for i in members], dtype=np.int64)
        hints = np.array([runs[i].ego_s for i in members], dtype=np.float64)
        out = np.empty((len(members), 8))
        if ego_road.road.ego_poses(ego_road.elevation, egos.states, rows, hints, out):
            for i, row in zip(members, out.tolist()):
                posed[i] = row
    return posed


def _pose_ego(run: RunState, t: float, pre: list[float] | None) -> None:
    """A run's ego posed; `pre`: its pose, station, offset and elevation from `_ego_poses`
    (None: found here)."""
    plan, ego_road, e = run.bound, run.ego_road, run.ego
    if pre is not None:
        x, y, heading, run.ego_s, run.ego_t, run.ego_offset, z, grade = pre
    else:
        run.ego_offset = None  # (`record` asks the road)
        if run.ego_agent is not None:
            pose_scripted_ego(run, t, run.dt)
        v = e.row.tolist()  # (one read of its row in the egos' block)
        x, y, heading = v[X], v[Y], v[HEADING]
        if run.ego_agent is None:
            run.ego_s, run.ego_t = ego_road.road.project(x, y, run.ego_s)
    if run.ego_s >= ego_road.road.length and not run.left_road:
        # Past the end of its road or route: `s` stays at the end, the map has nothing
        # beyond, and the run goes on off the map. Say so once (a route through the
        # junction keeps the ego on the network); from then on it is in no lane: its
        # `lane_offset` is unknown (NaN), which fails `stay in lane`.
        rx, ry, h = ego_road.road.reference_pose(run.ego_s)
        if (x - rx) * math.cos(h) + (y - ry) * math.sin(h) > 0.5 * plan.ego.length_m:
            run.left_road = True
            run.events.append(Event(t, "left_road", {"actor": "ego", "road": plan.ego.road,
                                                     "s": round(float(run.ego_s), 3)}))
    if not run.networked and not run.leaders_stale:  # (networked runs find leaders by position)
        run.leaders.moved(len(run.agents))  # the ego, last member; agents move in their phase
    # The ego follows the road height; its dynamics feel the grade along its heading.
    if pre is None:
        z, grade = ego_road.elevation.at(run.ego_s)
    if grade:
        grade *= math.cos(heading - ego_road.road.reference_pose(run.ego_s)[2])
    pitch = math.atan(grade)
    run.ego_z, e.pitch, run.ego_grade = z, pitch, grade
    run.physics.set_pose("ego", x, y, z + plan.ego.height_m / 2, heading, pitch)
    if run.networked:
        run.world_pose["ego"] = (x, y, heading)


def record(runs: list[RunState], recs: list[Record], k: int, egos: StateBlock, fleets: Fleets | None = None) -> None:
    """Over the batch: every actor's fields at sample k but the clearance: a batch's records
    whose agents `pose` posed as arrays (`fleets`) in one kernel call (`_record_rows`: the
    egos' states from their block, the agents' from the pose table), else the egos' from
    their block at once and each run's agents; then what only some runs record."""
    shared = BatchRows.of(recs)
    cols = fleets.record_columns(runs) if shared is not None and fleets is not None else None
    if cols is not None:
        rows, live = shared
        stl: list[float] = []
        for run in runs:
            stl += _ego_station(run)
        _record_rows(rows.block[k], rows.first, live, egos.states, egos.index([run.ego_row for run in runs]),
                     _EGO_COLUMNS, np.array(stl).reshape(-1, 3), *cols)
        for run, rec in zip(runs, recs):
            if rec.extras:
                _record_extras(run, rec, k)
        return
    ego_rows = egos.records([run.ego_row for run in runs], _EGO_COLUMNS, len(FIELDS) - 1)
    for run, rec, ego_row in zip(runs, recs, ego_rows):
        _record(run, rec, k, ego_row)


@kernel
def _record_rows(block, first, live, states, ego_rows, columns, stl, pose, flat, counts, pose_lo, cell0):
    """Sample k's rows of a batch's live runs (`block`: the batch's rows of sample k, run
    live[j]'s actors from row first[live[j]]): the ego's state (`vehicle.ego_record` of block
    row ego_rows[j]) and its station, offset and lane offset `stl[j]`, then its counts[j]
    agents' (`agents.agent_row`: pose table columns pose_lo[j] on, block slots cell0[j] on)."""
    for j in range(live.size):
        c = first[live[j]]
        row = block[c]
        ego_record(states[ego_rows[j]], columns, row)
        row[_S], row[_T], row[_LANE_OFFSET] = stl[j, 0], stl[j, 1], stl[j, 2]
        for i in range(counts[j]):
            agent_row(block[c + 1 + i], pose, pose_lo[j] + i, flat, cell0[j] + i)


def _ego_station(run: RunState) -> tuple[float, float, float]:
    """The ego's recorded station, offset and lane offset [m] (NaN once it left its road)."""
    s, t = run.ego_s, run.ego_t
    if run.left_road:
        return s, t, math.nan
    off = run.ego_offset  # (`pose` found it where it posed the ego in a batch)
    return s, t, off if off is not None else run.ego_road.road.lane_offset(s, t)


def _record(run: RunState, rec: Record, k: int, ego_row: list[float]) -> None:
    """A run's fields at sample k, the ego's state in `ego_row` already."""
    ego_row[_S], ego_row[_T], ego_row[_LANE_OFFSET] = _ego_station(run)
    fleet = run.fleet
    if fleet.rows is not None:  # agents posed one by one: the rows at once
        rec.block[k, :, :-1] = [ego_row, *fleet.rows]
    else:
        rec.block[k, 0, :-1] = ego_row
        fleet.record(rec.block, k)
    if rec.extras:
        _record_extras(run, rec, k)


def _record_extras(run: RunState, rec: Record, k: int) -> None:
    """What some runs record at sample k (`Record.extras`): lanes, edges, ends, lane states,
    variables, margins to red lights and stop signs."""
    for name, lanes in rec.lanes.items():  # `lane_id(A)`: only in runs that read it
        lanes[k] = run.lane_number(name)
    for name, edges in rec.edges.items():  # `road_edge(A)`: to the outer edge of A's road
        if name == "ego":
            road, s, t = run.ego_road.road, run.ego_s, run.ego_t
        else:
            a = run.agent_by_name[name]
            road, s, t = run.agent_roads[name].road, a.s, a.t
        lo, hi = road.paved_band_t(s)
        edges[k] = min(t - lo, hi - t)
    for name, ends in rec.ends.items():  # `road_end(A)`: left to the end of A's road or route
        if name == "ego":
            road, s = run.ego_road.road, run.ego_s
        else:
            road, s = run.agent_roads[name].road, run.agent_by_name[name].s
        ends[k] = road.length - s
    if rec.wrong_ways or rec.offs:  # `wrong_way(A)`, `off_lanes(A)`
        lanestate.record(run, rec, k)
    for name, values in rec.variables.items():  # `var(P)`: as it is at sample k
        values[k] = run.variables[name]
    if run.lights is not None:  # (the conditions of this sample's steps read them)
        _red_margins(run, rec, k, k * run.dt)
    if run.signs is not None:  # `stop_sign(A)`: to the next stop sign not stopped for
        rec.sign_margins["ego"][k] = run.signs.margin("ego", run.ego_s + 0.5 * run.ego_plan.length_m, run.ego.speed,
                                                      run.sign_stations["ego"])
        for a in run.agents:
            rec.sign_margins[a.name][k] = run.signs.margin(a.name, a.s + 0.5 * a.length_m, a.speed,
                                                           run.sign_stations[a.name])


def _red_margins(run: RunState, rec: Record, k: int, t: float) -> None:
    """Every actor's margin to its next red at sample k (signal `red_light`)."""
    rec.margins["ego"][k] = run.lights.red_margin("ego", run.ego_s + 0.5 * run.ego_plan.length_m,
                                                  run.stop_stations["ego"], t)
    for a in run.agents:
        rec.margins[a.name][k] = run.lights.red_margin(a.name, a.s + 0.5 * a.length_m, run.stop_stations[a.name], t)


def environment(runs: list[RunState], recs: list[Record], k: int, ts: list[float]) -> None:
    """Over the batch: environment steps (`at 3 s fog visibility 30 m`) fire on the state just
    recorded."""
    for run, rec, t in zip(runs, recs, ts):
        if run.environment_script is not None:
            advance_environment_script(run, rec, k, t)


def variables(runs: list[RunState], recs: list[Record], k: int, ts: list[float]) -> None:
    """Over the batch: the steps that set scenario variables fire on the state just recorded
    (a value set now is read from the next sample on: `record` took the values at sample k)."""
    for run, rec, t in zip(runs, recs, ts):
        if run.variable_script is not None:
            advance_variable_script(run, rec, k, t)


def lights(runs: list[RunState], recs: list[Record], k: int, ts: list[float]) -> None:
    """Over the batch: light changes fire on the state just recorded (their conditions, as the
    environment's and the variables', read the red margins `record` took with the lights as
    they were); then each light's state, and the margins again with the changes that fired
    now (`red_margin` gives the same for the same states: recomputing is exact)."""
    for run, rec, t in zip(runs, recs, ts):
        if run.lights is None:
            continue
        if run.light_script is not None:
            advance_light_script(run, rec, k, t)
            _red_margins(run, rec, k, t)
        for name in rec.lights:
            rec.lights[name][k] = run.lights.state(name, t)


def collisions(runs: list[RunState], recs: list[Record], k: int, ts: list[float]) -> list[bool]:
    """Over the batch: each actor's clearance at sample k (from the poses `record` wrote
    into the step's rows) and `collision` events (every run's pairs in one compiled call:
    `collision.clearances_batch`); whether each ego collided."""
    shared = BatchRows.of(recs)
    if shared is not None:  # (a batch's records: its step's rows at once)
        rows, live = shared
        return clearances_rows(rows.block[k], rows.first, live, rows.sizes,
                               [(rec.names, run, t) for run, rec, t in zip(runs, recs, ts)])
    return clearances_batch([(rec.block[k], rec.names, rec.footprints, run, t) for run, rec, t in zip(runs, recs, ts)])


def outputs(runs: list[RunState], recs: list[Record], k: int, ts: list[float]) -> None:
    """Over the batch: the stack's latencies, the command, the objects it saw, named steps'
    states."""
    for run, rec, t in zip(runs, recs, ts):
        latency, recorded = run.stack.latency, rec.latency
        for node in LATENCY_NODES:
            recorded[node][k] = latency[node]
        rec.outputs["control.steer"][k], rec.outputs["control.accel"][k] = run.command
        rec.objects[k] = run.stack.objects_seen
        if rec.steps:  # named steps: ended on the state just recorded
            for name, code in run.step_states(t).items():
                rec.steps[name][k] = code


def end(runs: list[RunState], recs: list[Record], k: int, ts: list[float]) -> list[bool]:
    """Over the batch: whether `end when ...` holds on the state just recorded."""
    out = []
    for run, rec, t in zip(runs, recs, ts):
        script = run.end_script
        if script is not None:
            script.advance(t, condition_checker(run, rec, k), lambda clause, time_s: None)
            if script.done:
                run.events.append(Event(t, "end", {}))
        out.append(script is not None and script.done)
    return out


def conditions(runs: list[RunState], recs: list[Record], k: int) -> None:
    """Over the batch: the `when` conditions that several runs' scripts ask alike at sample
    k, evaluated together before `triggers` (`triggers.prefetch`)."""
    prefetch(runs, recs, k)


def triggers(runs: list[RunState], recs: list[Record], k: int, ts: list[float]) -> None:
    """Over the batch: behaviours waiting for the first recorded state start; scripted steps
    fire."""
    for run, rec, t in zip(runs, recs, ts):
        run.recorded = (rec, k)  # live behaviour settings read the state just recorded
        if run.deferred:
            for agent, clause in run.deferred:
                run._start_behavior(agent, clause, t)
            run.deferred.clear()
        if run.scripts:
            advance_scripts(run, rec, k, t)
            if rec.steps:  # steps that fired now are started at this sample
                for name, code in run.step_states(t).items():
                    rec.steps[name][k] = code
        if run.faults.openers:  # `when C for W` faults: on the state as recorded at k, these steps included
            run.faults.open_windows(t, condition_checker(run, rec, k))


def sense(runs: list[RunState], ts: list[float]) -> list[Exception | None]:
    """Over the batch: each run's sensors that are due capture, faults act on the frames and
    frames leave for the stack, which takes those that have arrived. Per run, the exception
    that stopped it there, or None."""
    errors: list[Exception | None] = [None] * len(runs)
    for i, (run, t) in enumerate(zip(runs, ts)):
        try:
            _sense(run, t)
            _frames(run, t)
        except Exception as exc:  # noqa: BLE001 - a stack failure is the run's outcome
            errors[i] = exc
    return errors


def _sense(run: RunState, t: float) -> None:
    """A run's sensors that are due capture; faults act on them; frames leave for the stack."""
    for name, sensor in run.sensors.items():
        if t + 1e-9 < run.sensor_next[name]:
            continue
        run.sensor_next[name] += sensor.period_s
        for f in run.faults.for_target(name):
            f.before_capture(sensor, t)
        frame = sensor.capture(run, t)
        frame.ego_pose = run.ego_pose()  # what was true at the capture travels with the frame
        if "hit_body" in frame.data:
            # (sorted(set()) gives np.unique's list, faster at every size)
            frame.actors = {b: run.actor_by_body(b) for b in sorted(set(frame.data["hit_body"].tolist()))}
        for env in run.environment:  # weather and light act on what the sensor captured
            frame = env.on_frame(sensor, frame, run.rng(f"environment:{env.keyword}:{name}"))
        delay = 0.0
        for f in run.faults.for_target(name):
            frame, extra = f.on_frame(frame, t)
            delay += extra
            if frame is None:
                break
        if frame is not None:
            run._frame_seq += 1
            heapq.heappush(run.inflight, (t + delay, run._frame_seq, frame))


def _frames(run: RunState, t: float) -> None:
    """Frames that have arrived reach the stack."""
    while run.inflight and run.inflight[0][0] <= t + 1e-12:
        _, _, frame = heapq.heappop(run.inflight)
        run.stack.on_frame(frame, t)


def stack(runs: list[RunState], ts: list[float]) -> list[Exception | None]:
    """Over the batch: each run's stack steps, the stacks of a class with a batched step
    (`step_batch(stacks, times)`: the default stack's control cycles in one kernel call)
    together, others one by one. Per run, the exception that stopped its stack, or None."""
    stacks = [run.stack for run in runs]
    kind = type(stacks[0]) if stacks else None
    if all(type(s) is kind for s in stacks) and hasattr(kind, "step_batch"):  # (the usual batch: one class)
        return kind.step_batch(stacks, ts)
    errors: list[Exception | None] = [None] * len(runs)
    groups: dict[type, list[int]] = {}  # (in the runs' order)
    for i, s in enumerate(stacks):
        groups.setdefault(type(s), []).append(i)
    for cls, members in groups.items():
        step_batch = getattr(cls, "step_batch", None)
        if step_batch is not None:
            for i, error in zip(members, step_batch([stacks[i] for i in members], [ts[i] for i in members])):
                errors[i] = error
            continue
        for i in members:
            try:
                runs[i].stack.step(ts[i], runs[i].dt)
            except Exception as exc:  # noqa: BLE001 - a stack failure is the run's outcome
                errors[i] = exc
    return errors


def ego(runs: list[RunState], ts: list[float], egos: StateBlock) -> list[bool]:
    """Over the batch: commands due by now take effect; each ego moves over the step: the
    dynamics of every driven ego at once (`vehicle.StateBlock.step`: one kernel call on the
    egos' block), an OSI stack's update, or, scripted, as agents do (a stack's commands are
    then recorded, not applied). Whether each ego's state stayed finite."""
    driven: list[RunState] = []
    for run, t in zip(runs, ts):
        dt = run.dt
        queue = run.command_queue
        while queue and queue[0][0] <= t + 1e-12:
            _, steer, accel = queue.pop(0)
            run.command = (steer, accel)
        if run.ego_agent is None and run.move_host is not None:
            run.move_host(run.ego, t + dt)
        elif run.ego_agent is None:
            driven.append(run)
        else:
            if run.leaders_stale and not run.networked:  # it may ask for its leader
                run.leaders.rebuild()
                run.leaders_stale = False
            run.move(run.ego_agent, t, dt)
            run.ego.vx, run.ego.accel = run.ego_agent.speed, run.ego_agent.accel
    if not runs:
        return []
    return egos.step([(r.ego_row, *r.command, r.ego_grade) for r in driven], [r.vehicle_params for r in driven],
                     [run.ego_row for run in runs])


def agents(runs: list[RunState], ts: list[float], fleets: Fleets) -> None:
    """Over the batch: every agent's step, all runs' at once as arrays where they allow it
    (`agents.Fleets.step`), else one after another in declaration order, each seeing the
    earlier ones moved."""
    for run, t in fleets.step(runs, ts):
        leaders, networked = run.leaders, run.networked
        if run.leaders_stale and not networked:
            leaders.rebuild()
            run.leaders_stale = False
        for i, a in enumerate(run.agents):
            run.move(a, t, run.dt)
            if not networked:  # agents later in the order see this one where it is now
                leaders.moved(i)
