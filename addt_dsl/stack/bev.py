"""The default stack `bev`: perception → tracker → lattice planner → controller on a bus.

Timing follows the paper's BEV stack: sensor frames arrive (possibly late); a frame older
than `stale` on arrival is discarded (out-of-order avoidance); each node publishes at
`t + latency`, latency from the per-node model (measured trend and jitter, drawn from
generators seeded by the run seed, scaled to `latency_target`) or, with `latency
measured`, the measured compute time (HIL-like). End-to-end latency is
actuation time minus the sensor timestamp the command derives from.
"""

from __future__ import annotations

import math
import time as _time

import numpy as np

from addt_dsl.kernel import hypot, kernel, tan
from addt_dsl.plan import LIGHT_STATES
from addt_dsl.registry import STACKS
from addt_dsl.runtime.fastroad import project_boxed, reference_pose_at
from addt_dsl.specs import stacks as S
from addt_dsl.specs.stacks import NODE_NAMES, PERCEPTIONS
from addt_dsl.stack.bus import Bus
from addt_dsl.stack.latency import Jitter, load_models
from addt_dsl.stack.control import ControlBlock, Controller
from addt_dsl.stack.nodes import EgoBody, GroundTruthPerception, LatticePlanner, Obj, Tracker, time_to_cover, unchanged
from addt_dsl.units import to_si
from addt_dsl.vehicles import CAR

CROSSING_SIN = 0.5  # an object whose box is turned more than 30 deg from the road ...
CROSSING_MIN_SPEED = 0.5  # [m/s] ... and moves across it faster than this is predicted across it
# [m/s^2] a cyclist turned across the road at rest may set off towards the ego's path at this
# (a rider starting from a standstill: 1-1.5 m/s^2): it is predicted so until it moves
SET_OFF_ACCEL = 1.5
_KIND_CODES = {"pedestrian": 1, "cyclist": 2}  # `_road_frame`'s kinds (0 any other)


def road_frame_objects(road, tracked: list, t0: float) -> list[tuple]:
    """The planner's objects: the tracks `tracked` in road coordinates (`LatticePlanner`'s
    tuples), the ego at offset `t0` [m]; one kernel call over all of them (`_road_frame`)."""
    if not tracked:
        return []
    rows = np.array([(o.x, o.y, o.heading, o.vx, o.vy, o.ax, o.ay, o.length, o.width) for o in tracked],
                    dtype=np.float64)
    kinds = np.array([_KIND_CODES.get(o.kind, 0) for o in tracked], dtype=np.int64)
    out = np.empty((len(tracked), 8))
    _road_frame(*road.table, road.boxes(), rows, kinds, t0, out)
    return list(map(tuple, out.tolist()))


@kernel
def _trig_arg(a):
    """Raise where CPython's math.cos / math.sin of `a` would (an infinite angle)."""
    if a - a != 0.0 and a == a:
        raise ValueError("math domain error")
    return a


@kernel
def _road_frame(tab, ds, last_i, length, boxes, rows, kinds, t0, out):
    """Each track (rows[j]: x, y, heading [rad], vx, vy, ax, ay, length, width; kinds[j]:
    `_KIND_CODES`) in the road's frame into out[j]: station, offset, velocity along and
    across, extent along and across the road, acceleration along and across."""
    for j in range(rows.shape[0]):
        ox, oy, oh, ovx, ovy, oax, oay, olen, owid = (rows[j, 0], rows[j, 1], rows[j, 2], rows[j, 3], rows[j, 4],
                                                      rows[j, 5], rows[j, 6], rows[j, 7], rows[j, 8])
        so, to = project_boxed(tab, ds, last_i, length, boxes, ox, oy)
        # Velocity along the road, and the box's extent along and across it.
        hdg = reference_pose_at(tab, ds, last_i, length, so)[2]
        c, s = math.cos(_trig_arg(hdg)), math.sin(hdg)
        rc, rs = abs(math.cos(_trig_arg(oh - hdg))), abs(math.sin(oh - hdg))
        v_t = ovy * c - ovx * s
        a_s, a_t = oax * c + oay * s, oay * c - oax * s
        # Across the road only for an object turned across it (a crossing pedestrian or
        # cyclist, a vehicle turning): for one aligned with the road, the lateral velocity
        # from 10 Hz positions alone is noise (0.24-0.30 m/s from the tracker's filter for a
        # car, ±1 m/s before it), too much to extrapolate over the horizon. A pedestrian's
        # box is square (a detector's box axis says nothing of where it walks): its
        # direction of motion tells whether it crosses.
        turned = rs
        if kinds[j] == 1 and hypot(ovx, ovy) > CROSSING_MIN_SPEED:
            turned = abs(math.sin(_trig_arg(math.atan2(ovy, ovx) - hdg)))
        if not (turned > CROSSING_SIN and abs(v_t) > CROSSING_MIN_SPEED):
            v_t = a_t = 0.0
            # A rider turned across the road and (still) at rest: its box says where it
            # will go before its velocity does (the tracked velocity needs ~0.5 s to pass
            # the test above; junction_cyclist's rider sets off 9 m ahead of the ego).
            if kinds[j] == 2 and turned > CROSSING_SIN and hypot(ovx, ovy) < CROSSING_MIN_SPEED:
                a_t = math.copysign(SET_OFF_ACCEL, t0 - to)
        out[j, 0], out[j, 1], out[j, 2], out[j, 3] = so, to, ovx * c + ovy * s, v_t
        out[j, 4], out[j, 5] = olen * rc + owid * rs, olen * rs + owid * rc
        out[j, 6], out[j, 7] = a_s, a_t


def _ground_truth(settings, ctx):
    return GroundTruthPerception(settings, ctx.rng("perception"), ctx.rng("perception.weak"))


def _learned(settings, ctx):
    from addt_dsl.stack.learned import LearnedPerception  # torch: only when asked for

    return LearnedPerception(settings, ctx)


def _camera(settings, ctx):
    from addt_dsl.stack.camera_perception import CameraPerception  # opencv: only when asked for

    return CameraPerception(settings, ctx)


def _camera_bev(settings, ctx):
    from addt_dsl.stack.camera_bev import CameraBevPerception  # torch: only when asked for

    return CameraBevPerception(settings, ctx)


# How each perception mode builds its node (importing torch or opencv only for the mode that
# needs them); what each reads and what the compiler checks: `specs.stacks.PERCEPTIONS`.
BUILDERS = {"ground_truth": _ground_truth, "learned": _learned, "camera": _camera, "camera_bev": _camera_bev}
assert set(BUILDERS) == set(PERCEPTIONS)


class StackError(RuntimeError):
    """Raised by the stack's watchdog (e.g. non-finite commands)."""


@STACKS.implements
class BevStack(S.BevStack):
    def tensor_sites(self) -> dict:
        """Tensor fault sites (site name → torch module); empty unless perception is a network."""
        modules = getattr(self.perception, "tensor_modules", None)
        return modules() if modules else {}

    def __init__(self, settings: dict, ctx):
        self.settings = {p.name: settings.get(p.name, p.default) for p in self.params}
        self.ctx = ctx
        self.bus = Bus()
        self.latency_models = load_models(self.settings["latency_target"])
        self.measured = self.settings["latency"] == "measured"
        self.jitter = self.settings["latency"] == "model"
        # Per node, its latency [s] for a count of objects: the trend, or (jitter) drawn with a
        # generator of the node's own from the run seed, so the draws repeat bit for bit.
        models = self.latency_models
        self._latency_of = {n: Jitter(models[n], ctx.rng(f"latency.{n}")).sample if self.jitter
                            else models[n].median for n in NODE_NAMES}
        self.perception = self._make_perception()
        # A fault on the node `perception` draws from the sites this mode's node has.
        self.nodes = {**type(self).nodes, "perception": tuple(self.perception.sites)}
        # The filter weighs positions and velocities by the detector's stated noises.
        self.tracker = Tracker(float(self.settings["track_max_age"]),
                               getattr(self.perception, "position_noise_m", None),
                               getattr(self.perception, "velocity_noise_mps", None))
        # The ego's declared body and friction: the planner's boxes and braking limits.
        self.body = EgoBody(float(ctx.ego_length_m), float(ctx.ego_width_m), float(ctx.ego_mass_kg),
                            float(ctx.ego_mu))
        self.planner = LatticePlanner(self.settings, self.body)
        self.cruise = self.planner.cruise  # the setting (the planner's may rise to clear a junction)
        self.controller = Controller(self.settings, ctx.wheelbase_m, self.body)
        self._alone: bool | None = None  # `_control_alone`, once the fault schedule is bound
        self._planner_corrupt = None  # `_planner_sites`, likewise
        self.aeb_stage = 0
        self.emergency = False
        self.signs_stopped: tuple[float, ...] = ()  # stations of the stop-sign lines it has stopped for
        self.planner_period = 1.0 / float(self.settings["planner_rate"])
        self.control_period = 1.0 / float(self.settings["control_rate"])
        self.next_plan_s = 0.0
        self.next_control_s = 0.0
        self.plan = None
        self.plan_stamp = None  # sensor stamp the current plan derives from
        self.tracks_stamp = None
        self.command = (0.0, 0.0)
        self.latency = {n: 0.0 for n in (*NODE_NAMES, "e2e")}
        self.pipeline_s = 0.0
        self.objects_seen = 0
        self.synthetic_objects = int(self.settings["synthetic_objects"])
        # Lidar name -> the distance [m] it is sure to see a car head-on at (passing through
        # the oncoming lane; none for camera perception: the ego never passes there).
        self.sight_m: dict[str, float] = {}

    def _make_perception(self):
        mode = self.settings["perception"]
        self.perception_input = PERCEPTIONS[mode].frame_key
        return BUILDERS[mode](self.settings, self.ctx)

    # ---- timing helpers
    def _latency(self, node: str, objects: int, started: float, time_s: float) -> float:
        base = _time.perf_counter() - started if self.measured else self._latency_of[node](objects)
        timing_faults = self.ctx.faults.by_target.get(node)
        lat = base + sum(f.extra_latency(node, time_s, base) for f in timing_faults) if timing_faults else base
        self.latency[node] = lat
        return lat

    def corrupt(self, site: str, value: float) -> float:
        # Called for every value through every site (~10 per control cycle): the fault-free
        # path is one dict lookup.
        kinds = self.ctx.faults.by_target.get(site)
        if kinds:
            now = self.ctx.now
            for f in kinds:
                value = f.on_value(site, value, now)
        return value

    def upset(self, node) -> None:
        """Memory faults in `node`'s stored state, before the node reads it (`FaultSchedule.upset`)."""
        self.ctx.faults.upset(node, self.ctx.now)

    # ---- inputs
    def on_frame(self, frame, arrive_s: float) -> None:
        """A sensor frame arrives at the stack at `arrive_s`."""
        if self.perception_input not in frame.data:
            return  # a frame of a sensor this perception does not read (IMU, GNSS, the other of lidar/camera)
        if arrive_s - frame.stamp_s > float(self.settings["stale"]):
            self.ctx.event("stale_frame", sensor=frame.sensor, age_s=arrive_s - frame.stamp_s)
            return
        started = _time.perf_counter()
        sensor = self.ctx.sensor(frame.sensor)
        if frame.sensor not in self.sight_m and self.perception_input == "hit_body":
            self.sight_m[frame.sensor] = lidar_sight(sensor.settings, sensor.nominal,
                                                     int(getattr(self.perception, "min_hits", 2)))
        # Measurements leave the vehicle frame through the pose the ego had at the capture.
        objs = self.perception.run(frame, sensor, frame.ego_pose, self.corrupt)
        if self.synthetic_objects:
            objs = objs + synthetic_objects(self.synthetic_objects, frame.ego_pose)
        self.objects_seen = len(objs)
        # What perception reported, in world coordinates: perception-error studies compare it
        # with the ground truth in the trace (addt_dsl.studies).
        self.ctx.event("detections", sensor=frame.sensor, stamp_s=frame.stamp_s,
                       objects=[[o.x, o.y, o.heading] for o in objs])  # lists: JSON-stable (bridge)
        lat = self._latency("perception", len(objs), started, arrive_s)
        self.bus.publish("objects", objs, frame.stamp_s, arrive_s + lat)

    # ---- the per-step tick
    def step(self, time_s: float, dt: float):
        error = self.step_batch([self], [time_s])[0]
        if error is not None:
            raise error
        return self.command

    @classmethod
    def step_batch(cls, stacks: list[BevStack], times_s: list[float]) -> list[Exception | None]:
        """One step of each stack at its time [s] (a batch's runs): messages, the planner, and
        the control cycle where due, the controllers without fault sites or measured latency
        in one call (`ControlBlock.command`). Per stack, the exception that stopped it, or None."""
        errors: list[Exception | None] = [None] * len(stacks)
        alone: list[int] = []
        batched: list[int] = []
        for i, (stack, time_s) in enumerate(zip(stacks, times_s)):
            try:
                if not stack._tick(time_s):
                    continue
                if stack.plan is None:
                    stack.command = (0.0, 0.0)
                else:
                    (alone if stack._control_alone() else batched).append(i)
            except Exception as exc:  # noqa: BLE001 - the run's outcome
                errors[i] = exc
        if len(batched) == 1:  # (one cycle: the block's arrays cost more than they save)
            alone, batched = alone + batched, []
        for i in alone:
            try:
                stacks[i]._run_control(times_s[i])
            except Exception as exc:  # noqa: BLE001 - the run's outcome
                errors[i] = exc
        if batched:
            egos, roads = [], []
            for i in batched:
                ctx = stacks[i].ctx
                egos.append((*ctx.ego_pose(), ctx.ego_station()))
                roads.append(ctx.ego_road()[0])
            ctrls = [stacks[i].controller for i in batched]
            for i, x in zip(batched, ControlBlock.holding(ctrls).command(ctrls, egos, roads)):
                if isinstance(x, Exception):
                    errors[i] = x
                    continue
                stack = stacks[i]
                try:  # (batched: no timing fault on the node, latency not measured)
                    lat = stack.latency["control"] = stack._latency_of["control"](0)
                    stack._commanded(times_s[i], *x, lat)
                except Exception as exc:  # noqa: BLE001 - the run's outcome
                    errors[i] = exc
        return errors

    def _tick(self, time_s: float) -> bool:
        """Messages due by `time_s` [s] arrive and the planner runs where due; whether the
        control cycle is due."""
        self.ctx.now = time_s
        if self.bus.due(time_s) or time_s + 1e-9 >= self.next_plan_s:
            self._deliver(time_s)
        if time_s + 1e-9 >= self.next_control_s:
            self.next_control_s += self.control_period
            return True
        return False

    def _deliver(self, time_s: float) -> None:
        """Messages due by `time_s` [s] arrive; the planner runs on fresh tracks or its timer."""
        fresh_tracks = False
        for msg in self.bus.deliver_until(time_s):
            if msg.topic == "objects":
                started = _time.perf_counter()
                self.upset(self.tracker)
                self.tracker.update(msg.data, msg.stamp_s, self.corrupt)
                lat = self._latency("tracker", len(msg.data), started, time_s)
                self.bus.publish("tracks", None, msg.stamp_s, time_s + lat)
            elif msg.topic == "tracks":
                self.tracks_stamp = msg.stamp_s
                fresh_tracks = True
            elif msg.topic == "plan":
                self.plan, self.plan_stamp = msg.data, msg.stamp_s
                self.controller.follow(self.plan)
                # Pipeline latency of the newest information in use: sensor stamp → plan out.
                self.pipeline_s = msg.deliver_s - msg.stamp_s
        # The planner runs on fresh tracks (event-driven, like a ROS callback) and on its
        # timer when none come (dropped frames), replanning on predicted tracks.
        if fresh_tracks or time_s + 1e-9 >= self.next_plan_s:
            # The timer is a fallback for missing frames: half a period of slack lets a
            # frame that is merely a little late still trigger the replan itself.
            self.next_plan_s = time_s + 1.5 * self.planner_period
            self._run_planner(time_s)

    def _control_alone(self) -> bool:
        """Whether this stack's control cycle runs alone: a fault on the controller's sites or
        timing, or latency measured on the clock (the schedule's targets are fixed once bound)."""
        if self._alone is None:
            self._alone = self.measured or self._targeted(("control", *Controller.sites))
        return self._alone

    def _targeted(self, sites) -> bool:
        """Whether a fault of the schedule targets one of `sites`."""
        targets = self.ctx.faults.by_target
        return any(s in targets for s in sites)

    def _planner_sites(self):
        """The planner's `corrupt`: this stack's, or `unchanged` where no fault targets the
        planner's sites (the schedule's targets are fixed once bound)."""
        if self._planner_corrupt is None:
            self._planner_corrupt = self.corrupt if self._targeted(LatticePlanner.sites) else unchanged
        return self._planner_corrupt

    def _run_planner(self, time_s: float) -> None:
        started = _time.perf_counter()
        road, road_id = self.ctx.ego_road()
        x, y, heading, speed = self.ctx.ego_pose()
        s0, t0 = road.project(x, y, self.ctx.ego_station())
        lane0 = road.lane_at(s0, t0) or self.ctx.ego_lane
        self.upset(self.tracker)
        self.upset(self.planner)
        # Confirmed tracks only. A detector without velocity output leaves a track seen once
        # with a guessed velocity of 0: a car first seen 35 m ahead of an ego at 20 m/s,
        # taken as standing, set off an emergency stop and the full AEB stage in the first
        # 0.1 s of a learned-perception overtake. The second sighting (0.1 s later at
        # 10 Hz) gives the velocity.
        # Weak tracks (seen once with fewer returns than `min_hits`) wait for their confirmation.
        tracked = [o for o in self.tracker.objects_at(time_s) if o.velocity_known and not o.weak]
        objs = road_frame_objects(road, tracked, float(t0))
        hdg0 = heading - float(road.reference_pose(s0)[2])
        stop = self._stop_sign(float(s0), speed, self.ctx.stop_line_ahead(float(s0)))
        give_way, judged = self._give_way(float(s0), float(t0), speed, tracked, objs)
        if give_way is not None and (stop is None or give_way < stop[0]):
            stop = (give_way, LIGHT_STATES["red"])  # wait before the junction like at a red light
        # An object whose path crosses the ego's in the junction, with a gap judged long
        # enough (or the ego clearing its zone before it arrives), is the gap rule's: the
        # planner's road-frame checks, which take it as coming head-on along the ego's
        # path, would stop the ego inside its path.
        objs = [ob for i, ob in enumerate(objs) if i not in judged]
        oncoming = None
        if self.sight_m and self.settings["pass_oncoming"] == "on":
            # An oncoming car not seen may come at the road's speed limit (the ego's cruise
            # speed where the map gives none).
            limit = road.speed_limit(float(s0))
            oncoming = (max(self.sight_m.values()), limit if limit is not None else self.cruise,
                        self._pass_end(float(s0), stop))
        plan = self.planner.plan((float(s0), float(t0), lane0), speed, objs, road, road_id, time_s,
                                 self._planner_sites(), (speed * math.cos(hdg0), speed * math.sin(hdg0)), stop,
                                 oncoming)
        if plan.aeb_stage != self.aeb_stage:
            self.ctx.event("aeb", stage=plan.aeb_stage, ttc_s=plan.ttc_s if math.isfinite(plan.ttc_s) else None)
            self.aeb_stage = plan.aeb_stage
        if self.planner.emergency != self.emergency:
            self.ctx.event("emergency_brake", on=self.planner.emergency, decel=plan.brake)
            self.emergency = self.planner.emergency
        lat = self._latency("planner", len(objs), started, time_s)
        stamp = self.tracks_stamp if self.tracks_stamp is not None else time_s
        self.bus.publish("plan", plan, stamp, time_s + lat)

    # Stop signs: the ego stops at the line of the next stop sign of the map on its route as at
    # a red light, and counts it done once it has stood (below `SIGN_STOPPED_MS`) with its
    # front within `SIGN_ZONE_M` before the line; then the junction's gap judgement decides
    # when it goes. The judge's `stop_sign` margin asks for less (0.1 m/s within 4 m).
    SIGN_STOPPED_MS = 0.05
    SIGN_ZONE_M = 3.0

    def _stop_sign(self, s0: float, speed: float, stop):
        """The stop line the planner holds the ego at: a light's (`stop`: station, state
        code; or None) or the next stop sign's it has not stopped for, whichever is nearer."""
        sign = self.ctx.stop_sign_ahead(s0, self.signs_stopped)
        if sign is not None and speed < self.SIGN_STOPPED_MS \
                and sign - (s0 + 0.5 * self.body.length_m) <= self.SIGN_ZONE_M:
            self.signs_stopped = (*self.signs_stopped, sign)
            self.ctx.event("stop_sign", station_m=round(sign, 3))
            sign = self.ctx.stop_sign_ahead(s0, self.signs_stopped)
        if sign is not None and (stop is None or sign < stop[0]):
            return sign, LIGHT_STATES["red"]
        return stop

    def _pass_end(self, s0: float, stop) -> float:
        """The station [m] a pass through the oncoming lane must be over by: the next junction
        on the route or stop line (a light's, or where the ego gives way), inf without one.
        No overtaking into a junction; what stands before a stop line is a queue."""
        end = stop[0] if stop is not None else math.inf
        junction = self.ctx.junction_ahead(s0)
        return min(end, junction[0]) if junction is not None else end

    # Gap acceptance at junctions (`yield_gap` > 0, 1.5 s by default): before it reaches the
    # part of a junction on its route where another road user's path crosses its own, the ego
    # judges the gap. Each moving tracked object (other than traffic ahead in its own lane,
    # which the planner follows) is predicted along a straight line at its velocity; the
    # conflict zone is where the ego's path (its route's lane centre through the junction)
    # comes within both half widths + `YIELD_LATERAL_M` of that line. The ego occupies it from
    # its front's arrival until its rear has left, the object likewise (times from the ego's
    # speed accelerating at `YIELD_ACCEL`, up to its cruise and the junction's curve speed,
    # and from the object's constant speed). It goes when the object clears the zone before
    # the ego arrives or arrives `yield_gap` after the ego has left; otherwise it waits before
    # the zone: at the junction entry for crossing traffic, inside the junction short of the
    # conflict point for an oncoming car it turns across (creeping up to it). Once it cannot
    # stop before the zone at `YIELD_COMMIT_DECEL` it clears it if it can leave before the
    # object arrives, else it brakes. Priority from the map's
    # lights: with a green light at the entry, crossing traffic that can still stop at its
    # own red (at `YIELD_COMMIT_DECEL`) is not waited for; oncoming traffic is (a permissive
    # green) and so is a red-light runner that can no longer stop. The map's signs
    # (`ctx.junction_rule`, runtime/signs.py): with priority (a 301 sign, or on a priority road: 306) crossing
    # traffic that can still stop short of the zone braking at `PRIORITY_DECEL` (or at its
    # own measured deceleration, if harder) is not waited for; behind a yield sign (205,
    # R1-2) the ego reaches the junction entry at `YIELD_SIGN_SPEED` at most (StVO 8(2):
    # a moderate speed that shows it will wait), slowing at `YIELD_SIGN_DECEL`; without a
    # sign it gives way as behind a yield sign, at its own speed.
    YIELD_SIGN_SPEED = to_si(20.0, "km/h")[0]  # [m/s]
    YIELD_SIGN_DECEL = 1.0  # [m/s^2]
    YIELD_SIGN_LEAD_S = 1.5  # [s]
    PRIORITY_DECEL = 2.5  # [m/s^2] traffic that can stop braking this hard (or as it brakes) gives way
    YIELD_LATERAL_M = 0.5
    YIELD_WAIT_CLEARANCE_M = 1.5
    YIELD_ACCEL = 1.5  # [m/s^2] below the planner's 2 m/s^2: the estimate errs long
    YIELD_COMMIT_DECEL = 4.0  # [m/s^2]
    CLEAR_MAX_SPEED = to_si(30.0, "km/h")[0]  # [m/s] clearing a junction: up to its curve speed, at most this
    YIELD_CLEARED_S = 0.5  # [s] an object that leaves the zone this long before the ego arrives is gone
    REACTION_S = 0.2  # [s] from the plan to the brakes' full effect
    YIELD_STEP_M = 0.5
    STOP_MARGIN_M = 1.0  # the wait station is this far before the zone (the stop adds its own gap)

    def _give_way(self, s0: float, t0: float, speed: float, tracked: list, objs) -> tuple[float | None, set]:
        """The station [m] the ego's front waits at before a junction's conflict zone, or
        None (go), and the indices of the objects whose gap it judged long enough or whose
        zone it clears; `tracked` are the planned-for tracks, `objs` the same in road coordinates."""
        judged: set = set()
        self.planner.cruise = self.cruise
        margin = float(self.settings["yield_gap"])
        if margin <= 0.0:
            return None, judged
        junction = self.ctx.junction_ahead(s0)
        if junction is None:
            return None, judged
        entry, cx, cy, exit_ = junction
        road, _ = self.ctx.ego_road()
        half_len = 0.5 * self.body.length_m
        front = s0 + half_len
        length, width = self.body.length_m, self.body.width_m
        lo = max(s0, entry - half_len - 2.0)
        hi = min(exit_ + half_len + 2.0, road.length)
        if hi <= lo:
            return None, judged
        # Stations on a fixed grid (not from the ego's station): the waiting point moves with
        # the objects, not with the ego's last millimetre (the OSI bridge's rounding).
        step = self.YIELD_STEP_M
        ss = np.arange(math.ceil(lo / step) * step, hi, step)
        if len(ss) == 0:
            return None, judged
        xs, ys, hs, _ = road.sample_arrays(ss, 0.0)
        v_top = self._junction_speed(road, lo, hi)
        approach = float(road.reference_pose(s0)[2])
        rule = self.ctx.junction_rule(s0)
        green = self._green_at(entry, s0)
        wait, clear, cover = None, False, math.inf
        if rule == "yield" and front < entry:
            # The planner's speed follows its cruise about `YIELD_SIGN_LEAD_S` late: aim that much early.
            d = max(entry - front - self.YIELD_SIGN_LEAD_S * speed, 0.0)
            cover = math.sqrt(self.YIELD_SIGN_SPEED ** 2 + 2.0 * self.YIELD_SIGN_DECEL * d)
        for i, (o, (so, to, v_s, *_rest)) in enumerate(zip(tracked, objs)):
            if abs(to - t0) < 1.8 and (so > s0 or v_s > 0.0):
                # Traffic ahead in the ego's lane (the planner follows it) or following it
                # (its path is the ego's own: no conflict to give way to, and braking for it
                # would stop the ego in front of it).
                continue
            v = math.hypot(o.vx, o.vy)
            if v < 0.5:
                continue  # standing: the planner's checks keep the ego off one on its path
            ux, uy = o.vx / v, o.vy / v
            # A vehicle's box axis gives its direction better than its velocity estimated
            # from 10 Hz positions (±15 deg for 0.1 m noise: metres across at the conflict
            # point): the axis, turned to the way it moves; the velocity for a walker.
            if o.kind != "pedestrian" and abs(math.cos(o.heading) * ux + math.sin(o.heading) * uy) > 0.7:
                way = 1.0 if math.cos(o.heading) * ux + math.sin(o.heading) * uy > 0.0 else -1.0
                ux, uy = way * math.cos(o.heading), way * math.sin(o.heading)
            cover = min(cover, self._cover_speed(o, ux, uy, v, approach, cx, cy, front, entry, exit_,
                                                 s0, speed, v_top))
            # The ego's box at each station, turned with the path: its half extent across the
            # object's line and along it.
            rel = hs - math.atan2(uy, ux)
            sin_r, cos_r = np.abs(np.sin(rel)), np.abs(np.cos(rel))
            across = 0.5 * (o.width + length * sin_r + width * cos_r) + self.YIELD_LATERAL_M
            reach = 0.5 * (o.length + length * cos_r + width * sin_r)
            dx, dy = xs - o.x, ys - o.y
            along = dx * ux + dy * uy
            hit = (np.abs(dx * uy - dy * ux) < across) & (along + reach > 0.0)
            if not hit.any():
                continue
            zone_s = ss[hit]
            near = np.abs(dx * uy - dy * ux) < across + self.YIELD_WAIT_CLEARANCE_M - self.YIELD_LATERAL_M
            d_in = float(np.min(along[hit] - reach[hit]))
            d_out = float(np.max(along[hit] + reach[hit]))
            t_o_in, t_o_out = max(0.0, d_in) / v, d_out / v
            # Stations of the ego's centre while its box overlaps the object's lane: its front
            # enters at the first plus half a length. It waits where its box keeps
            # `YIELD_WAIT_CLEARANCE_M` from the object's (a left turn starts almost
            # antiparallel to the oncoming lane: the lateral gap closes slowly along the path).
            zone_front = float(zone_s[0]) + half_len
            wait_front = float(ss[near & (along + reach > 0.0)][0]) + half_len
            crossing = abs(math.sin(math.atan2(uy, ux) - approach)) > 0.7
            if rule == "priority" and crossing and \
                    v * v < 2.0 * max(self.PRIORITY_DECEL, -(o.ax * ux + o.ay * uy)) * max(d_in, 0.0):
                # Its own sign holds it: not waited for, nor taken by the planner's road-frame
                # checks as crossing the ego's lane. Once it could stop short of the zone only
                # braking harder than it does (and than `PRIORITY_DECEL`) it is the gap rule's
                # and the planner's again: a driver who ignores the sign.
                judged.add(i)
                continue
            if green and crossing and v * v < 2.0 * self.YIELD_COMMIT_DECEL * max(d_in, 0.0):
                continue  # crossing traffic at its red: it stops
            t_e_in = time_to_cover(front, zone_front, speed, v_top, self.YIELD_ACCEL)
            t_e_out = time_to_cover(s0, float(zone_s[-1]), speed, v_top, self.YIELD_ACCEL)
            if t_e_in > t_o_out + self.YIELD_CLEARED_S or t_o_in > t_e_out + margin:
                judged.add(i)
                continue  # the gap is long enough
            line = wait_front - self.STOP_MARGIN_M
            if speed * speed > 2.0 * self.YIELD_COMMIT_DECEL * max(line - front, 0.0) and speed > 0.5:
                # Past its waiting point: stop short of the zone if the brakes still can (the
                # stop keeps `LatticePlanner.STOP_GAP_M` before the station), else clear the
                # zone as fast as the junction's curves allow.
                line = zone_front
                if speed * speed / (2.0 * self.body.max_brake) + self.REACTION_S * speed > line - front:
                    # It cannot stop short: it clears the zone if it can leave before the
                    # object arrives, else it brakes as hard as it may (a car turning across
                    # its path passes in front of a stopped ego; one clearing slowly is hit).
                    v_clear = self._junction_speed(road, lo, hi, self.CLEAR_MAX_SPEED)
                    if time_to_cover(s0, float(zone_s[-1]), speed, v_clear, self.YIELD_ACCEL) < t_o_in:
                        clear = True
                        judged.add(i)
                        continue
                    line = max(line, front)
            if wait is None or line < wait:
                wait = line
        if wait is not None:
            clear = False
        # Clearing: the plan's speed may rise over the cruise speed to the junction's curve
        # speed, at most `CLEAR_MAX_SPEED` (a slow cruise, 10 km/h, would leave the ego in
        # the other's path for seconds).
        if clear:
            self.planner.cruise = max(self.cruise, self._junction_speed(road, lo, hi, self.CLEAR_MAX_SPEED))
        elif cover < self.cruise:
            self.planner.cruise = cover
        return wait, judged

    # Covering the brake: an oncoming vehicle that reaches the junction's middle about when
    # the ego does may turn across its path (its turn is seen only once its heading turns:
    # esmini's ltap-od turns 0.7 s before the contact, in the near half of the junction).
    # The ego keeps a speed from which it slows at `COVER_DECEL` to `COVER_SPEED` at the
    # junction entry, until that vehicle is past the junction's middle or the ego is.
    COVER_SPEED = 2.0  # [m/s]
    COVER_DECEL = 2.0  # [m/s^2]
    COVER_WINDOW_S = 3.0

    def _cover_speed(self, o, ux, uy, v, approach, cx, cy, front, entry, exit_, s0, speed, v_top) -> float:
        """The speed cap [m/s] an object sets as an oncoming vehicle that may turn across the
        ego's path at the junction (middle at `cx`, `cy`), or inf."""
        if math.cos(math.atan2(uy, ux) - approach) > -0.7:
            return math.inf  # not oncoming
        to_mid = (cx - o.x) * ux + (cy - o.y) * uy
        middle = 0.5 * (entry + exit_)
        if to_mid < 0.0 or front >= middle:
            return math.inf  # it is past the middle, or the ego is
        t_e = time_to_cover(front, middle, speed, v_top, self.YIELD_ACCEL)
        if to_mid / v > t_e + self.COVER_WINDOW_S:
            return math.inf  # it comes later
        d = max(entry - front, 0.0)
        return math.sqrt(self.COVER_SPEED ** 2 + 2.0 * self.COVER_DECEL * d)

    def _junction_speed(self, road, lo: float, hi: float, cruise: float | None = None) -> float:
        """The speed [m/s] the ego drives through the junction at most: `cruise` (default its
        cruise speed), capped by the curve speed of the sharpest bend between stations `lo` and `hi`."""
        cruise = self.cruise if cruise is None else cruise
        _, kappa = road.curvature_ahead(lo, hi - lo)
        k = float(np.max(np.abs(kappa))) if len(kappa) else 0.0
        return min(cruise, math.sqrt(self.planner.max_lateral_accel / k)) if k > 1e-6 else cruise

    def _green_at(self, entry: float, s0: float) -> bool:
        """Whether a green light governs the ego's approach to the junction at `entry`."""
        stop = self.ctx.stop_line_ahead(s0)
        return stop is not None and stop[1] == LIGHT_STATES["green"] and stop[0] <= entry + 1.0

    def _run_control(self, time_s: float) -> None:
        """The control cycle through every fault site of the controller."""
        started = _time.perf_counter()
        road, _ = self.ctx.ego_road()
        x, y, heading, speed = self.ctx.ego_pose()
        s_now, t_now = road.project(x, y, self.ctx.ego_station())
        steer, accel = self.controller.command(self.plan, (x, y, heading, speed), road,
                                               float(s_now), float(t_now), self.control_period,
                                               self.corrupt)
        self._commanded(time_s, steer, accel, self._latency("control", 0, started, time_s))

    def _commanded(self, time_s: float, steer: float, accel: float, lat: float) -> None:
        """The controller's command leaves after its latency `lat` [s]."""
        if not (math.isfinite(steer) and math.isfinite(accel)):
            raise StackError(f"non-finite command steer={steer!r} accel={accel!r}")
        self.command = (steer, accel)
        # End-to-end: sensor timestamp → actuation, for the newest frame the command derives from.
        self.latency["e2e"] = self.pipeline_s + lat
        self.ctx.apply_command_at(time_s + lat, steer, accel)


# What a lidar must return from a car to see it (passing through the oncoming lane): a box
# of the catalogue car's width, 1.5 m tall on the road, facing it.
SIGHT_TARGET_WIDTH_M = CAR.width_m
SIGHT_TARGET_HEIGHT_M = 1.5


def lidar_sight(settings: dict, mount, min_hits: int) -> float:
    """The distance [m] up to which a lidar (`settings` in SI, `mount` its nominal
    extrinsics) returns at least `min_hits` rays from a car head-on wherever its box falls
    between the rays: per channel whose ray at that distance meets the box's height,
    floor(angular width / ray spacing) rays. A level 360-ray channel sees one to 54 m.
    Counted from where the lidar first sees it: a roof lidar's rays pass over a car right
    beside its mount (from 2.5 m, at 30 deg down, over 1.5 m within 1.7 m), which is no
    limit on how far it sees."""
    rays, channels = int(settings["rays"]), int(settings["channels"])
    spacing = float(settings["fov"]) / rays
    elev = (np.linspace(-0.5, 0.5, channels) * float(settings["vfov"]) if channels > 1 else np.zeros(1)) \
        - float(mount.pitch)
    d = np.arange(1.0, float(settings["range"]) + 0.5, 0.5)
    z = float(mount.z) + d[:, None] * tan.over(elev[None, :])
    on_box = ((z > 0.0) & (z < SIGHT_TARGET_HEIGHT_M)).sum(axis=1)
    hits = on_box * np.floor(SIGHT_TARGET_WIDTH_M / (d * spacing))
    seen = np.nonzero(hits >= min_hits)[0]
    if not len(seen):
        return 0.0
    short = np.nonzero(hits[seen[0]:] < min_hits)[0]
    return float(d[seen[0] + short[0] - 1]) if len(short) else float(d[-1])


def synthetic_objects(count: int, ego_pose) -> list[Obj]:
    """`count` vehicles of the catalogue car's size keeping pace with the ego, off the road on both sides.

    Deterministic in `count` (no randomness: same RunSpec, same workload): object k sits
    on side (-1)^k in one of six rows 12 m, 15.5 m, ... 29.5 m from the ego's centre line,
    in columns 8 m apart along it (0, +8, -8, +16 m, ...: twelve objects per column, every
    slot distinct), heading and speed those of the ego. Far enough aside
    that no lane change of a road up to 6 lanes wide conflicts with them; they load the
    tracker, the planner's collision checks and the latency model like real objects.
    """
    x, y, heading, speed = ego_pose
    c, s = math.cos(heading), math.sin(heading)
    out = []
    for k in range(count):
        side = 1.0 if k % 2 == 0 else -1.0
        lateral = side * (12.0 + 3.5 * ((k // 2) % 6))
        column = k // 12  # 0, +8, -8, +16, -16 m along, then the next 12 objects
        along = 8.0 * ((column + 1) // 2) * (1.0 if column % 2 else -1.0) + 4.0 * ((k // 2) % 2)
        out.append(Obj(x + c * along - s * lateral, y + s * along + c * lateral, heading,
                       speed * c, speed * s, CAR.length_m, CAR.width_m))
    return out
