"""What a sweep will cost, known from the plan before any run starts (docs/limits.md).

The model, per run (the runtime's fixed clock: one physics step every `step_s`):

    samples           = duration / step + 1
    actor-steps       = samples x actors (the ego and every agent)
    lidar rays        = sum over lidars of rays x channels x rate x duration
    camera pixels     = sum over cameras and rigs of pixels per frame x rate x duration
    memory [bytes]    = RUN_BASE_BYTES + samples x 8 x (1 + TRACE_FIELDS x actors + LATENCY_SERIES)

    wall time [s]     = WALL_RUN_S + samples x (WALL_STEP_S + WALL_ACTOR_STEP_S x actors)
                        + lidar rays x WALL_LIDAR_RAY_S + camera pixels x WALL_CAMERA_PIXEL_S
                        + perception frames x the stack's per-frame network cost (`frame_cost`)

and per sweep: runs x each of them (simulated seconds = runs x duration). The memory
term is the trace the run keeps (runtime/trace.py: TRACE_FIELDS float64 signals per
actor per sample, a clock, latency series) over a fixed allowance for the interpreter,
the physics engine and the stack. Runs counts grid cells x samples x repeats without
building any of them; with assumptions and no sampler, cells an assumption rejects do
not run, so the count is exact up to EXACT_COUNT_CELLS cells and an upper bound beyond.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from addt_dsl.limits import Limits, beyond_message
from addt_dsl.plan import ScenarioPlan, resolve_settings
from addt_dsl.registry import SENSORS, STACKS
from addt_dsl.sweep import count_runs, grid_cell_count, sampled_params

# Interpreter, pybullet world, stack and sensors, before the trace: one inline run of
# examples/following.addt peaks at about 110 MB resident; torch (the learned stack) adds
# a few hundred MB, so the allowance covers both.
RUN_BASE_BYTES = 512 * 1024 ** 2
TRACE_FIELDS = 11  # float64 signals per actor per sample (runtime/trace.py ACTOR_FIELDS)
LATENCY_SERIES = 8  # per-node latency series of the stack, "e2e" included
EXACT_COUNT_CELLS = 100_000  # above this many grid cells assumptions are not evaluated to count runs

# Wall time of one run on one core [s], measured by benchmarks/bench_cost_model.py (probes
# of the `bev` stack with ground-truth perception, 10 ms steps; MEASURED below):
#   wall = WALL_RUN_S + steps x (WALL_STEP_S + WALL_ACTOR_STEP_S x actors)
#          + lidar rays x WALL_LIDAR_RAY_S + camera pixels x WALL_CAMERA_PIXEL_S
WALL_RUN_S = 0.06
WALL_STEP_S = 3.2e-5
WALL_ACTOR_STEP_S = 3.6e-5
WALL_LIDAR_RAY_S = 2.7e-7
WALL_CAMERA_PIXEL_S = 4.7e-7
MEASURED = ("2026-12-06, a 2-core machine shared with other work (so on the slow side); learned "
            "perception costs more per step than this model says")


@dataclass(frozen=True)
class CostEstimate:
    runs: int
    runs_exact: bool  # False: an upper bound (assumptions may reject grid cells)
    duration_s: float
    samples_per_run: int
    actors: int
    agent_steps_per_run: float
    lidar_rays_per_run: float
    run_memory_bytes: float
    camera_pixels_per_run: float = 0.0  # rendered (a camera's cost grows with its pixels, docs/twin.md)
    network_s_per_run: float = 0.0  # perception network inference [s] (the stack's `frame_cost`)

    @property
    def sim_seconds(self) -> float:
        return self.runs * self.duration_s

    @property
    def agent_steps(self) -> float:
        return self.runs * self.agent_steps_per_run

    @property
    def lidar_rays(self) -> float:
        return self.runs * self.lidar_rays_per_run

    @property
    def camera_pixels(self) -> float:
        return self.runs * self.camera_pixels_per_run

    @property
    def run_wall_s(self) -> float:
        """Estimated wall time of one run on one core [s] (`wall_seconds_per_run`)."""
        return wall_seconds_per_run(self)

    @property
    def wall_s(self) -> float:
        """Estimated wall time of the sweep on one core [s]: divide by the workers."""
        return self.runs * self.run_wall_s

    def lines(self) -> list[str]:
        """The estimate as `addtc check` and `addtc plan` print it."""
        runs = f"{self.runs:,}" if self.runs_exact else f"at most {self.runs:,}"
        pixels = f", {self.camera_pixels_per_run:.4g} camera pixels" if self.camera_pixels_per_run else ""
        sweep_pixels = f", {self.camera_pixels:.4g} camera pixels" if self.camera_pixels_per_run else ""
        return [f"cost estimate: {runs} run(s) x {self.duration_s:g} s = {self.sim_seconds:.4g} simulated s",
                f"  per run: {self.samples_per_run:,} steps x {self.actors} actor(s) = "
                f"{self.agent_steps_per_run:.4g} actor-steps, {self.lidar_rays_per_run:.4g} lidar rays{pixels}, "
                f"about {self.run_memory_bytes / 1024 ** 2:,.0f} MiB",
                f"  sweep: {self.agent_steps:.4g} actor-steps, {self.lidar_rays:.4g} lidar rays{sweep_pixels}",
                f"  wall time: about {_duration(self.run_wall_s)} per run, {_duration(self.wall_s)} for the sweep "
                "on one core (divide by --jobs)"]


def wall_seconds_per_run(est: CostEstimate) -> float:
    """One run's wall time on one core [s], from the measured coefficients (`WALL_*`)."""
    return (WALL_RUN_S + est.samples_per_run * WALL_STEP_S + est.agent_steps_per_run * WALL_ACTOR_STEP_S
            + est.lidar_rays_per_run * WALL_LIDAR_RAY_S + est.camera_pixels_per_run * WALL_CAMERA_PIXEL_S
            + est.network_s_per_run)


def _duration(seconds: float) -> str:
    """`0.8 s`, `12 min`, `3.1 h`, `4.2e+03 days`: a wall time as a person reads it."""
    if seconds < 120:
        return f"{seconds:.2g} s"
    if seconds < 2 * 3600:
        return f"{seconds / 60:.3g} min"
    if seconds < 3 * 86400:
        return f"{seconds / 3600:.3g} h"
    return f"{seconds / 86400:.3g} days"


def estimate(plan: ScenarioPlan) -> CostEstimate:
    runs, exact = run_count(plan)
    return _per_run(plan, runs, exact)


def run_wall_seconds(plan: ScenarioPlan) -> float:
    """One run's estimated wall time on one core [s] (no run counting: cheap per run)."""
    return _per_run(plan, 1, True).run_wall_s


def _per_run(plan: ScenarioPlan, runs: int, exact: bool) -> CostEstimate:
    samples = int(math.floor(plan.duration_s / plan.step_s + 1e-9)) + 1
    actors = 1 + len(plan.agents)
    nominal = plan.nominal_params()
    rays = pixels = network_s = 0.0
    stack = plan.ego.stack  # None: a scripted ego without a stack
    frame_cost = getattr(STACKS.get(stack.name), "frame_cost", None) if stack is not None else None
    per_frame = frame_cost({k: v for k, v in stack.settings.items() if isinstance(v, str)}) if frame_cost else None
    for actor in plan.actors():
        for sensor in actor.sensors:
            cls = SENSORS.get(sensor.name)
            pixels_per_frame = getattr(cls, "pixels_per_frame", None)
            if cls is None or (sensor.name != "lidar" and pixels_per_frame is None):
                continue
            spec = {p.name: p.default for p in cls.params}
            try:
                spec.update(resolve_settings(sensor.settings, nominal))
            except (ValueError, ArithmeticError, KeyError):
                pass  # a setting that needs a sampled value: the defaults stand in
            if sensor.name == "lidar":
                rays += float(spec["rays"]) * float(spec["channels"]) * float(spec["rate"]) * plan.duration_s
            else:
                pixels += pixels_per_frame(spec) * float(spec["rate"]) * plan.duration_s
            if per_frame is not None and actor is plan.ego and sensor.name == per_frame[0]:
                network_s += per_frame[1] * float(spec["rate"]) * plan.duration_s
    memory = RUN_BASE_BYTES + samples * 8.0 * (1 + TRACE_FIELDS * actors + LATENCY_SERIES)
    return CostEstimate(runs=runs, runs_exact=exact, duration_s=plan.duration_s, samples_per_run=samples,
                        actors=actors, agent_steps_per_run=float(samples * actors), lidar_rays_per_run=rays,
                        run_memory_bytes=memory, camera_pixels_per_run=pixels, network_s_per_run=network_s)


def run_count(plan: ScenarioPlan) -> tuple[int, bool]:
    """(runs, exact): no grid cell or sample is built to count them."""
    sweep = plan.sweep
    cells = grid_cell_count(plan)
    if sweep.sampler and sampled_params(plan):
        return cells * sweep.sampler.count * sweep.repeat, True
    if not plan.assumptions:
        return cells * sweep.repeat, True
    if cells <= EXACT_COUNT_CELLS:
        return count_runs(plan), True
    return cells * sweep.repeat, False


def over_thresholds(est: CostEstimate, limits: Limits) -> list[tuple[str, str]]:
    """(threshold name, message) for each cost threshold the estimate exceeds; none when
    `limits.allow_large`."""
    if limits.allow_large:
        return []
    runs = min(est.runs, limits.run_cap) if limits.run_cap else est.runs  # `--limit N` runs N of them
    checks = (
        ("runs", "the sweep's run count", runs),
        ("sim_seconds", "the sweep's simulated time [s]", runs * est.duration_s),
        ("agent_steps", "the sweep's actor-steps", runs * est.agent_steps_per_run),
        ("agent_steps_per_run", "one run's actor-steps", est.agent_steps_per_run),
        ("lidar_rays_per_run", "one run's lidar rays", est.lidar_rays_per_run),
        ("camera_pixels_per_run", "one run's rendered camera pixels", est.camera_pixels_per_run),
        ("run_memory_bytes", "one run's modelled memory [bytes]", est.run_memory_bytes),
        ("run_wall_seconds", "one run's estimated wall time [s]", est.run_wall_s),
        ("wall_seconds", "the sweep's estimated wall time on one core [s]", runs * est.run_wall_s),
    )
    return [(name, beyond_message(what, value, name, getattr(limits, name)))
            for name, what, value in checks if value > getattr(limits, name)]


__all__ = ["CostEstimate", "EXACT_COUNT_CELLS", "LATENCY_SERIES", "RUN_BASE_BYTES", "TRACE_FIELDS", "estimate",
           "over_thresholds", "run_count", "run_wall_seconds", "wall_seconds_per_run"]
