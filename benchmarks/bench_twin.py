"""Speed and fidelity figures of the physics twin.

Run: PYTHONPATH=. python benchmarks/bench_twin.py [--quick]

Speed: microseconds per physics step with 5 and 20 vehicles (our loop's own physics:
ego dynamics, agent kinematics, body poses, collision/clearance; and pybullet's
stepSimulation for reference, which the loop does not need), milliseconds per lidar
scan and per camera frame, and the real-time factor of examples/overtake.addt with
ground-truth perception. Fidelity: emergency stop vs theory, the friction limit in a
constant-radius turn, lane-change overshoot at 30 m/s.
"""

from __future__ import annotations

import math
import statistics
import sys
import time
from pathlib import Path

import _figures as figures_json

ROOT = Path(__file__).resolve().parents[1]
QUICK = "--quick" in sys.argv
JSON_PATH = sys.argv[sys.argv.index("--json") + 1] if "--json" in sys.argv else None


def best_of(fn, repeat: int = 5, number: int = 1) -> float:
    """Best per-call wall time [s] over `repeat` batches of `number` calls (the machine is shared)."""
    fn()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        for _ in range(number):
            fn()
        times.append((time.perf_counter() - t0) / number)
    return min(times)


def compile_spec(source: str):
    from addt_dsl.compiler import compile_source
    from addt_dsl.sweep import expand

    result = compile_source(source)
    assert result.plan is not None, [str(d) for d in result.diagnostics]
    return expand(result.plan).specs[0]


def traffic_source(n_agents: int, sensors: str = "sensor lidar rate 10 Hz rays 360 range 80 m",
                   duration: float = 10.0) -> str:
    agents = "\n".join(
        f"  agent a{i} car on r lane {-1 - i % 3} at {60 + 25 * (i // 3)} m speed 20 m/s {{\n"
        f"    behavior idm speed {18 + i % 5} m/s\n  }}" for i in range(n_agents))
    return f"""
scenario traffic_{n_agents} {{
  duration {duration} s
  road r {{
    line length 1500 m
    arc length 300 m curvature 0.003 /m
    line length 1000 m
    lanes right 3 width 3.5 m
  }}
  ego car on r lane -2 at 20 m speed 20 m/s {{
    stack bev cruise_speed 22 m/s
    {sensors}
  }}
{agents}
}}"""


# ---------------------------------------------------------------- physics step

def physics_step_us(n_vehicles: int) -> dict[str, float]:
    """Per-step cost of the loop's physics with `n_vehicles` (ego + agents)."""
    import numpy as np

    from addt_dsl.runtime import batch as X
    from addt_dsl.runtime.behaviors import advance
    from addt_dsl.runtime.vehicle import step as vehicle_step

    from addt_dsl.runtime.collision import clearances
    from addt_dsl.runtime.state import RunState

    run = RunState(compile_spec(traffic_source(n_vehicles - 1)))
    try:
        trace = X._loop([run])[0]  # move everyone into a realistic configuration first
        dt, names = run.dt, ["ego"] + [a.name for a in run.agents]
        sizes = {"ego": (run.ego_plan.length_m, run.ego_plan.width_m),
                 **{a.name: (a.length_m, a.width_m) for a in run.agents}}
        rows = np.zeros((len(names), 11))  # a step's rows of the record: x, y, heading first, the clearance last
        footprints = np.array([sizes[n] for n in names])

        def one_step():
            poses = {}
            for a in run.agents:
                road = run.agent_roads[a.name]
                x, y, h = road.pose(a.s, a.t)
                poses[a.name] = (x, y, h)
                run.physics.set_pose(a.name, x, y, 0.75, h)
            e = run.ego
            run.physics.set_pose("ego", e.x, e.y, 0.75, e.heading)
            poses["ego"] = (e.x, e.y, e.heading)
            rows[:, :3] = [poses[n] for n in names]
            clearances(rows, names, footprints, run, 0.0)
            vehicle_step(e, run.vehicle_params, 0.0, 0.0, dt)
            for a in run.agents:
                beh = run.longitudinal[a.name]
                advance(a, beh.accel(a, run, 0.0), 0.0, dt)
                a.s -= a.speed * dt  # stay in place: every repetition measures the same scene
            run.leaders.rebuild()  # stations changed outside the loop

        total = best_of(one_step, repeat=5, number=200)
        dyn = best_of(lambda: vehicle_step(run.ego, run.vehicle_params, 0.0, 0.0, dt), repeat=5, number=2000)
    finally:
        run.physics.close()

    # pybullet's own rigid-body step with the same number of dynamic boxes (reference).
    import pybullet as p

    cid = p.connect(p.DIRECT)
    try:
        p.setGravity(0, 0, -9.81, physicsClientId=cid)
        p.setTimeStep(0.01, physicsClientId=cid)
        p.createMultiBody(0, p.createCollisionShape(p.GEOM_PLANE, physicsClientId=cid), physicsClientId=cid)
        box = p.createCollisionShape(p.GEOM_BOX, halfExtents=[2.3, 0.95, 0.75], physicsClientId=cid)
        for i in range(n_vehicles):
            body = p.createMultiBody(1500.0, box, basePosition=[10.0 * i, 3.5 * (i % 3), 0.76], physicsClientId=cid)
            p.resetBaseVelocity(body, [20.0, 0.0, 0.0], physicsClientId=cid)
        bullet = best_of(lambda: p.stepSimulation(physicsClientId=cid), repeat=5, number=200)
    finally:
        p.disconnect(physicsClientId=cid)
    steps = len(trace.time)
    return {"loop_physics_us": total * 1e6, "ego_dynamics_us": dyn * 1e6,
            "pybullet_step_us": bullet * 1e6, "steps": steps}


def loop_step_us(n_vehicles: int) -> float:
    """Whole closed-loop step (stack, sensors, physics) per simulated step [us]."""
    from addt_dsl.runtime.execute import execute

    spec = compile_spec(traffic_source(n_vehicles - 1, duration=5.0))
    wall = best_of(lambda: execute(spec, keep_trace=False), repeat=3)
    return wall / (5.0 / spec.plan.step_s) * 1e6


# ---------------------------------------------------------------- sensors

def sensor_ms(sensor_line: str, n_agents: int = 5, repeat: int = 5) -> tuple[float, object]:
    from addt_dsl.runtime import batch as X

    from addt_dsl.runtime.state import RunState

    run = RunState(compile_spec(traffic_source(n_agents, sensors=sensor_line, duration=2.0)))
    try:
        X._loop([run])  # pose the bodies
        sensor = next(iter(run.sensors.values()))
        frame = sensor.capture(run, 0.0)
        return best_of(lambda: sensor.capture(run, 0.0), repeat=repeat) * 1e3, (frame, run.scene)
    finally:
        run.physics.close()


# ---------------------------------------------------------------- real-time factor

def overtake_rtf(runs: int = 5) -> tuple[float, float, bool]:
    from addt_dsl.compiler import compile_file
    from addt_dsl.runtime.execute import execute
    from addt_dsl.sweep import expand

    plan = compile_file(ROOT / "examples" / "overtake.addt").plan
    spec = expand(plan).specs[0]
    results = [execute(spec, keep_trace=False) for _ in range(runs)]
    rtfs = [r.sim_time_s / r.wall_time_s for r in results]
    same = len({r.digest for r in results}) == 1
    return statistics.median(rtfs), max(rtfs), same


# ---------------------------------------------------------------- fidelity

def fidelity() -> list[str]:
    import numpy as np

    from addt_dsl.runtime.vehicle import G, VehicleParams, VehicleState, step

    lines = []
    dt = 0.01
    for mu in (0.8, 0.4):
        p = VehicleParams.for_vehicle(mu=mu)
        s = VehicleState(0.0, 0.0, 0.0, 30.0)
        while s.vx > 0.0:
            step(s, p, 0.0, -12.0, dt)
        a, lost = 0.0, 0.0
        for _ in range(500):  # actuator chain alone: equivalent dead time
            d = (-12.0 - a) * min(1.0, dt / p.accel_lag_s)
            a += max(-p.jerk_limit * dt, min(p.jerk_limit * dt, d))
            lost += (1.0 - min(abs(a), mu * G) / (mu * G)) * dt
        base = 30.0 ** 2 / (2 * mu * G)
        lines.append(f"emergency stop 30 m/s, mu {mu}: {s.x:6.2f} m; v^2/(2 mu g) {base:6.2f} m "
                     f"+ lag {30.0 * lost:4.2f} m = {base + 30.0 * lost:6.2f} m "
                     f"({100 * (s.x / (base + 30.0 * lost) - 1):+.1f} %)")
    # Constant radius 40 m, slow speed ramp: where the circle is lost.
    p = VehicleParams.for_vehicle(mu=0.8)
    s, integral, t, radius = VehicleState(0.0, 0.0, 0.0, 5.0), 0.0, 0.0, 40.0
    ay_max, lost_at = 0.0, None
    while t < 110.0:
        dx, dy = s.x, s.y - radius
        r = math.hypot(dx, dy)
        err = r - radius
        c, sn = math.cos(s.heading), math.sin(s.heading)
        radial = (dx * (s.vx * c - s.vy * sn) + dy * (s.vx * sn + s.vy * c)) / r
        integral += err * dt
        step(s, p, p.wheelbase_m / radius + 0.05 * err + 0.1 * radial + 0.02 * integral, 5.0 + 0.2 * t - s.vx, dt)
        t += dt
        ay_max = max(ay_max, s.ay)
        if lost_at is None and err > 1.0:
            lost_at = (s.vx, s.slip_front, s.slip_rear)
        if err > 3.0:
            break
    lines.append(f"constant radius 40 m, mu 0.8: circle lost (drifts out) at {lost_at[0]:.2f} m/s "
                 f"(sqrt(mu g R) = {math.sqrt(0.8 * G * radius):.2f}); a_y max {ay_max:.2f} m/s^2 "
                 f"(mu g = {0.8 * G:.2f}); slip front {lost_at[1]:.3f} rad > rear {lost_at[2]:.3f} rad; "
                 f"K = {p.understeer_gradient * 1e3:.2f} mrad/(m/s^2)")
    # Lane change at 30 m/s: stack controller on the planner's smoothstep plan.
    from addt_dsl.runtime.fastroad import FastRoad
    from addt_dsl.road import build_road, line
    from addt_dsl.stack.control import Controller
    from addt_dsl.stack.nodes import Plan

    road = FastRoad(build_road("r", [line(2000.0)], 0, 2, 3.5).road("r"))
    car = VehicleState(*road.point(100.0, -5.25), 30.0)
    ctl = Controller({}, p.wheelbase_m)
    plan = Plan(-1, -1.75, 30.0, 100.0, -5.25, 90.0, 0.0)
    cmd, s_now, ts = (0.0, 0.0), 100.0, []
    for _ in range(1000):
        s_now, t_now = road.project(car.x, car.y, s_now)
        ts.append(t_now)
        new = ctl.command(plan, (car.x, car.y, car.heading, car.speed), road, s_now, t_now, dt, lambda k, v: v)
        step(car, p, *cmd, dt)
        cmd = new
    err = np.array(ts) + 1.75
    settle = dt * (len(err) - np.argmax(np.abs(err[::-1]) > 0.05))
    lines.append(f"lane change 3.5 m at 30 m/s (stack Controller): overshoot {err.max():.3f} m, "
                 f"within 5 cm after {settle:.2f} s")
    return lines


def main() -> None:
    print("physics twin benchmark" + (" (quick)" if QUICK else ""))
    figures = {"quick": QUICK, "fidelity": fidelity(), "physics_step_us": {}, "closed_loop_step_us": {},
               "lidar_ms_per_scan": {}, "camera_ms_per_frame": {}}
    for line in figures["fidelity"]:
        print("  " + line)
    for n in (5, 20):
        r = physics_step_us(n)
        figures["physics_step_us"][f"{n} vehicles"] = r
        print(f"  physics step, {n:2d} vehicles: loop physics {r['loop_physics_us']:7.1f} us "
              f"(ego dynamics {r['ego_dynamics_us']:5.1f} us); pybullet stepSimulation "
              f"{r['pybullet_step_us']:7.1f} us (reference, not used by the loop)")
        if not QUICK:
            us = figures["closed_loop_step_us"][f"{n} vehicles"] = loop_step_us(n)
            print(f"  full closed-loop step, {n:2d} vehicles: {us:7.1f} us "
                  f"(stack, lidar 10 Hz, physics)")
    for rays, channels in ((360, 1), (1024, 16), (2048, 32)):
        ms, _ = sensor_ms(f"sensor lidar rate 10 Hz rays {rays} channels {channels} range 100 m")
        figures["lidar_ms_per_scan"][f"{rays}x{channels}"] = ms
        print(f"  lidar {rays:4d} x {channels:2d} rays: {ms:6.2f} ms/scan")
    for w, h in ((160, 120), (320, 240), (640, 480)) if not QUICK else ((160, 120),):
        ms, (frame, scene) = sensor_ms(f"sensor camera rate 10 Hz width {w} height {h}", repeat=3)
        ms_noseg, _ = sensor_ms(f"sensor camera rate 10 Hz width {w} height {h} segmentation off", repeat=3)
        figures["camera_ms_per_frame"][f"{w}x{h}"] = {"with_segmentation": ms, "without_segmentation": ms_noseg}
        print(f"  camera {w:3d} x {h:3d}: {ms:6.1f} ms/frame ({ms_noseg:6.1f} without segmentation); "
              f"scene {scene.visual_triangles} triangles")
    median, best, same = overtake_rtf(3 if QUICK else 5)
    print(f"  examples/overtake.addt (first RunSpec, ground-truth perception): real-time factor "
          f"{median:.0f}x median, {best:.0f}x best; digest stable: {same}")
    figures["overtake_rtf_gt"] = {"median": median, "best": best, "digest_stable": same}
    figures_json.write(JSON_PATH, figures)


if __name__ == "__main__":
    main()
