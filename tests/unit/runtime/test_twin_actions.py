"""OpenSCENARIO-like actions as road-frame kinematics: acceleration settings that give
that acceleration, dynamics shapes, speed profiles (against the fake world)."""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from addt_dsl.runtime.behaviors import SHAPES, advance, blend
from tests.unit.runtime.test_twin_behaviors import DT, LANES, FakeWorld, agent, simulate, start


@pytest.mark.parametrize("keyword,settings", [
    ("cruise", {"speed": 20.0, "accel": 2.0}),
    ("walk", {"speed": 8.0, "accel": 2.0}),
    ("cross", {"speed": 8.0, "accel": 2.0}),
    ("overtake", {"speed": 20.0, "accel": 2.0}),
])
def test_an_acceleration_setting_gives_that_acceleration(keyword, settings):
    # The issue: `cross ... accel 2 m/s^2` reached 1.32 m/s after 3 s (a first-order lag).
    a = agent(speed=0.0)
    rows = simulate(a, start(keyword, a, FakeWorld(), **settings), FakeWorld(), 1.5)
    assert a.speed == pytest.approx(3.0, abs=1e-9)
    assert np.diff(rows[:, 3]) == pytest.approx(2.0 * DT)


def test_cruise_lands_on_its_target_without_overshoot():
    a = agent(speed=10.0)
    rows = simulate(a, start("cruise", a, FakeWorld(), speed=13.05, accel=2.0, decel=3.0), FakeWorld(), 3.0)
    assert rows[:, 3].max() <= 13.05 + 1e-9 and a.speed == pytest.approx(13.05, abs=1e-9)
    assert np.argmax(rows[:, 3] >= 13.05 - 1e-9) == pytest.approx(1.525 / DT, abs=1)


def test_brake_stops_at_its_to_speed():
    a = agent(speed=10.0)
    simulate(a, start("brake", a, FakeWorld(), decel=6.0, to_speed=4.03), FakeWorld(), 3.0)
    assert a.speed == pytest.approx(4.03, abs=1e-9)


@given(st.sampled_from(sorted(SHAPES)), st.floats(0.0, 1.0))
def test_shapes_run_from_0_to_1_monotonically(shape, u):
    assert blend(shape, 0.0) == (1.0 if shape == "step" else 0.0)
    assert blend(shape, 1.0) == pytest.approx(1.0)
    assert 0.0 <= blend(shape, u) <= 1.0 + 1e-12
    assert blend(shape, u) <= blend(shape, min(1.0, u + 0.01)) + 1e-12


@pytest.mark.parametrize("shape,mid", [("linear", 15.0), ("cubic", 15.0), ("sinusoidal", 15.0)])
def test_cruise_with_a_shape_and_duration_follows_the_shape(shape, mid):
    a = agent(speed=10.0)
    rows = simulate(a, start("cruise", a, FakeWorld(), speed=20.0, shape=shape, duration=4.0), FakeWorld(), 6.0)
    at = {round(t, 6): v for t, v in zip(rows[:, 0], rows[:, 3])}
    assert at[2.0] == pytest.approx(mid, abs=1e-9)
    assert at[1.0] == pytest.approx(10.0 + 10.0 * blend(shape, 0.25), abs=1e-9)
    assert at[4.0] == pytest.approx(20.0, abs=1e-9) and a.speed == pytest.approx(20.0, abs=1e-9)


@pytest.mark.parametrize("shape,peak", [("linear", 1.0), ("cubic", 1.5), ("sinusoidal", math.pi / 2)])
def test_a_shape_without_duration_peaks_at_the_rate_limit(shape, peak):
    a = agent(speed=20.0)
    rows = simulate(a, start("cruise", a, FakeWorld(), speed=11.0, decel=3.0, shape=shape), FakeWorld(), 8.0)
    accel = np.diff(rows[:, 3]) / DT
    assert accel.min() == pytest.approx(-3.0, abs=0.02)
    # Duration = peak slope * |dv| / rate.
    reached = rows[np.argmax(rows[:, 3] <= 11.0 + 1e-9), 0]
    assert reached == pytest.approx(peak * 9.0 / 3.0, abs=2 * DT)


def test_a_step_speed_change_takes_one_step():
    a = agent(speed=10.0)
    rows = simulate(a, start("cruise", a, FakeWorld(), speed=4.0, shape="step"), FakeWorld(), 1.0)
    assert rows[1, 3] == pytest.approx(4.0) and a.speed == pytest.approx(4.0)


@pytest.mark.parametrize("shape", ["linear", "cubic", "sinusoidal", "quintic"])
def test_lane_change_shapes(shape):
    a = agent(lane=-2)
    start("lane_change", a, FakeWorld(), to=-1, duration=4.0, shape=shape)
    rows = simulate(a, start("cruise", a, FakeWorld(), speed=10.0), FakeWorld(), 5.0)
    at = {round(t, 6): lat for t, lat in zip(rows[:, 0], rows[:, 2])}
    assert at[1.0] == pytest.approx(LANES[-2] + 3.5 * blend(shape, 0.25), abs=1e-9)
    assert at[2.0] == pytest.approx(LANES[-2] + 1.75, abs=1e-9)
    assert a.t == pytest.approx(LANES[-1])


def test_a_step_lane_change_jumps():
    a = agent(lane=-2)
    start("lane_change", a, FakeWorld(), to=-1, duration=4.0, shape="step")
    rows = simulate(a, start("cruise", a, FakeWorld(), speed=10.0), FakeWorld(), 0.1)
    assert rows[1, 2] == pytest.approx(LANES[-1])


# esmini speed-profile.xosc: entries (0 s, 0), (+4 s, 10), (+4 s, 4), (+2 s, 8) m/s.
ESMINI_TIMES, ESMINI_SPEEDS = [0.0, 4.0, 8.0, 10.0], [0.0, 10.0, 4.0, 8.0]


@pytest.mark.parametrize("shape", ["linear", "cubic", "sinusoidal"])
def test_speed_profile_meets_its_points(shape):
    a = agent(speed=0.0)
    beh = start("speed_profile", a, FakeWorld(), 1.0, times=ESMINI_TIMES, speeds=ESMINI_SPEEDS, shape=shape)
    rows = simulate(a, beh, FakeWorld(), 12.0, t0=1.0)
    at = {round(t, 6): v for t, v in zip(rows[:, 0], rows[:, 3])}
    for t, v in zip(ESMINI_TIMES, ESMINI_SPEEDS):
        assert at[round(1.0 + t, 6)] == pytest.approx(v, abs=0.1)
    assert rows[:, 3].max() == pytest.approx(10.0, abs=1e-9)  # the esmini peak (9.09 m/s before)
    assert a.speed == pytest.approx(8.0)


def test_speed_profile_starts_from_the_current_speed_and_steps_at_points():
    a = agent(speed=6.0)
    beh = start("speed_profile", a, FakeWorld(), times=[2.0, 3.0], speeds=[10.0, 5.0])
    rows = simulate(a, beh, FakeWorld(), 4.0)
    at = {round(t, 6): v for t, v in zip(rows[:, 0], rows[:, 3])}
    assert at[1.0] == pytest.approx(8.0) and at[2.0] == pytest.approx(10.0) and at[3.0] == pytest.approx(5.0)
    b = agent(speed=6.0)
    beh = start("speed_profile", b, FakeWorld(), times=[1.0, 2.0], speeds=[10.0, 5.0], shape="step")
    rows = simulate(b, beh, FakeWorld(), 3.0)
    at = {round(t, 6): v for t, v in zip(rows[:, 0], rows[:, 3])}
    assert at[0.99] == pytest.approx(6.0) and at[1.0] == pytest.approx(10.0)
    assert at[1.99] == pytest.approx(10.0) and at[2.0] == pytest.approx(5.0)


# speed-profile.xosc's Car1: followingMode follow, maxAcceleration 5, maxDeceleration 10,
# maxAccelerationRate 4, maxDecelerationRate 3 (m/s^2, m/s^3), started at 2 s from standstill.
FOLLOW = {"mode": "follow", "accel": 5.0, "decel": 10.0, "accel_rate": 4.0, "decel_rate": 3.0, "max_speed": 50.0}


def test_follow_profile_keeps_the_slopes_and_rounds_the_corners_at_the_jerk_limits():
    a = agent(speed=0.0)
    beh = start("speed_profile", a, FakeWorld(), 2.0, times=ESMINI_TIMES, speeds=ESMINI_SPEEDS, **FOLLOW)
    plan = [(s.t, s.v, s.k, s.j) for s in beh.plan]
    # By hand: the lines between the points have slopes 2.5, -1.5, 2 m/s^2. From rest the
    # acceleration rises at 4 m/s^3 to 2.5 m/s^2: 0.625 s, 0.5 * 4 * 0.625^2 m/s. The corner
    # onto v = 19 - 1.5 t (through (6 s, 10 m/s)) takes 4 / 3 s at -3 m/s^3 and gains
    # 2.5 * 4/3 - 1.5 * (4/3)^2 = 2/3 m/s: from v = 2.5 t1 - 5.78125, 2.5 t1 - 5.78125 + 2/3
    # = 19 - 1.5 (t1 + 4/3), t1 = 22.114583 / 4. Likewise onto v = 2 t - 16 (through (10 s,
    # 4 m/s)) at +4 m/s^3 for 0.875 s, and onto 8 m/s at -3 m/s^3 for 2/3 s.
    t1 = 22.114583333 / 4
    expected = [(2.0, 0.0, 0.0, 4.0), (2.625, 0.78125, 2.5, 0.0), (t1, 2.5 * t1 - 5.78125, 2.5, -3.0),
                (t1 + 4 / 3, 19 - 1.5 * (t1 + 4 / 3), -1.5, 0.0), (9.5625, 4.65625, -1.5, 4.0),
                (10.4375, 4.875, 2.0, 0.0), (35 / 3, 2 * 35 / 3 - 16 + 0.0, 2.0, -3.0), (37 / 3, 8.0, 0.0, 0.0)]
    assert np.array(plan) == pytest.approx(np.array(expected), abs=1e-6)
    rows = simulate(a, beh, FakeWorld(), 12.0, t0=2.0)
    at = {round(t, 6): v for t, v in zip(rows[:, 0], rows[:, 3])}
    # esmini 3.6's speeds of Car1 (tests/data/esmini-ref/traj/speed-profile.csv.gz, 4 decimals).
    for t, v in ((3.0, 1.7188), (6.0, 8.8855), (6.5, 9.0535), (10.0, 4.3828), (12.0, 7.8333), (12.5, 8.0)):
        assert at[t] == pytest.approx(v, abs=1e-4)
    assert not beh.ended(a, FakeWorld(), 12.3) and beh.ended(a, FakeWorld(), 12.34)


def test_follow_profile_to_one_speed_holds_the_acceleration_between_the_jerks():
    # By hand: up at 4 m/s^3 to a, hold it, down at 3 m/s^3 to 0 at 4 s, gaining 10 m/s:
    # a^2/8 + a (4 - a/4 - a/3) + a^2/6 = 10, 7 a^2 - 96 a + 240 = 0.
    acc = (96 - math.sqrt(96 ** 2 - 28 * 240)) / 14
    a = agent(speed=0.0)
    beh = start("speed_profile", a, FakeWorld(), 0.0, times=[4.0], speeds=[10.0], **FOLLOW)
    assert np.array([(s.t, s.k, s.j) for s in beh.plan]) == pytest.approx(np.array(
        [(0.0, 0.0, 4.0), (acc / 4, acc, 0.0), (4 - acc / 3, acc, -3.0), (4.0, 0.0, 0.0)]))
    rows = simulate(a, beh, FakeWorld(), 5.0)
    assert rows[:, 3].max() == pytest.approx(10.0) and a.speed == pytest.approx(10.0)
    assert np.diff(rows[:, 3]).max() == pytest.approx(acc * DT, abs=1e-9)


def test_follow_profile_cuts_a_slope_beyond_the_acceleration_limit():
    # 0 -> 10 m/s in 1 s needs 10 m/s^2; at most 5: the entry comes at 2 s (esmini's cut), and
    # without jerk limits the speed follows the 5 m/s^2 line.
    a = agent(speed=0.0)
    beh = start("speed_profile", a, FakeWorld(), 0.0, times=[0.0, 1.0, 3.0], speeds=[0.0, 10.0, 10.0],
                mode="follow", accel=5.0)
    rows = simulate(a, beh, FakeWorld(), 3.0)
    at = {round(t, 6): v for t, v in zip(rows[:, 0], rows[:, 3])}
    assert at[1.0] == pytest.approx(5.0, abs=1e-6) and at[2.0] == pytest.approx(10.0, abs=1e-6)


class LiveWorld(FakeWorld):
    """The fake world with other actors' lanes and live values (a signal: that actor's speed)."""

    def actor_lane(self, name):
        o = self.others[name]
        return min(LANES, key=lambda lane: abs(LANES[lane] - o.t))

    def live_value(self, expr):
        from addt_dsl.expr import eval_param_expr, signals_used
        speeds = {f"speed({n})": o.speed for n, o in self.others.items()}
        return eval_param_expr(_signals_as_params(expr), {k: speeds[k] for k in signals_used(expr)})


def _signals_as_params(expr):
    from addt_dsl.expr import Param, Signal
    if isinstance(expr, Signal):
        return Param(name=expr.name)
    updates = {}
    for field in ("left", "right", "arg"):
        if hasattr(expr, field):
            updates[field] = _signals_as_params(getattr(expr, field))
    return expr.model_copy(update=updates) if updates else expr


def test_a_live_speed_follows_another_actor():
    from addt_dsl.expr import Binary, Num, Signal
    lead = agent("lead", s=50.0, lane=-1, speed=10.0)
    world = LiveWorld(lead)
    a = agent(speed=5.0)
    target = Binary(op="+", left=Binary(op="*", left=Num(value=1.2), right=Signal(name="speed(lead)")),
                    right=Num(value=1.0))
    beh = start("cruise", a, world, speed=target, accel=3.0, decel=3.0)
    t = 0.0
    for k in range(800):  # the leader speeds up at 1 m/s^2 for 4 s, then holds
        lead.speed = 10.0 + min(4.0, t)
        advance(a, beh.accel(a, world, t), t, DT)
        t += DT
        if t > 6.0:
            assert a.speed == pytest.approx(1.2 * lead.speed + 1.0, abs=0.1)


def test_lane_change_to_the_lane_of_another_actor():
    ego = agent("ego", s=30.0, lane=-1)
    a = agent(lane=-2)
    world = LiveWorld(ego)
    start("lane_change", a, world, to_lane_of="ego", duration=2.0)
    simulate(a, start("cruise", a, world, speed=10.0), world, 3.0)
    assert a.lane == -1 and a.t == pytest.approx(LANES[-1])


@pytest.mark.parametrize("gap_setting,want", [({"distance": 20.0}, lambda v: 20.0),
                                               ({"time_gap": 1.5}, lambda v: 1.5 * v)])
def test_keep_gap_settles_on_the_gap_behind_a_moving_target(gap_setting, want):
    lead = agent("lead", s=80.0, speed=12.0)
    world = LiveWorld(lead)
    a = agent(s=0.0, speed=15.0)
    beh = start("keep_gap", a, world, target="lead", **gap_setting)
    simulate(a, beh, world, 40.0, others=[lead])
    gap = lead.s - a.s - 4.6
    assert gap == pytest.approx(want(a.speed), abs=0.2)
    assert a.speed == pytest.approx(12.0, abs=0.05)


def test_keep_gap_ahead_of_a_follower():
    tail = agent("tail", s=0.0, speed=10.0)
    world = LiveWorld(tail)
    a = agent(s=15.0, speed=10.0)
    simulate(a, start("keep_gap", a, world, target="tail", distance=25.0, side="ahead"), world, 40.0, others=[tail])
    assert a.s - tail.s - 4.6 == pytest.approx(25.0, abs=0.2)


@pytest.mark.parametrize("fraction", [0.25, 0.5, 0.75])
def test_synchronize_arrives_when_the_master_does(fraction):
    # A car at 11 m/s from s = 0 reaches s = 77 m at 7 s; the walker at s = 77 m must
    # be at t = -2.7 + fraction * 1.9 m then, whatever its start.
    car = agent("car", s=0.0, lane=-1, speed=11.0)
    world = LiveWorld(car)
    walker = agent(s=77.0, lane=-2, speed=0.0, length=0.5, width=0.5)
    target = -2.7 + fraction * 1.9
    beh = start("synchronize", walker, world, master="car", master_at=77.0, target_t=target,
                heading=math.pi / 2)
    rows = simulate(walker, beh, world, 7.0, others=[car])
    assert car.s == pytest.approx(77.0, abs=0.2)
    assert walker.t == pytest.approx(target, abs=0.05)
    assert rows[:, 3].max() < 2.0  # a walking pace, not a sprint at the end


def _synchronized(v0: float, target_s: float, final: float, master_speed: float, master_at: float,
                  seconds: float):
    car = agent("car", s=0.0, lane=-1, speed=master_speed)
    world = LiveWorld(car)
    a = agent(s=0.0, speed=v0)
    beh = start("synchronize", a, world, master="car", master_at=master_at, target_s=target_s,
                final_speed=final)
    rows = simulate(a, beh, world, seconds, others=[car])
    return a, beh, rows


def test_synchronize_on_the_line_to_its_final_speed_slows_at_one_rate():
    # esmini's linear case (SynchronizeAction::Step): 100 m in the master's 10 s from 15 m/s
    # to 5 m/s is one constant deceleration of 1 m/s^2 (15 = 2 * 100 / 10 - 5). The speed
    # that fills the time evenly (10 m/s) held up to the master's arrival is not it.
    a, beh, rows = _synchronized(15.0, 100.0, 5.0, 10.0, 100.0, 10.5)
    at = {round(t, 6): (s, v) for t, s, _, v, _ in rows}
    assert at[2.5][1] == pytest.approx(12.5, abs=0.05)
    assert at[7.5][1] == pytest.approx(7.5, abs=0.05)
    assert at[9.99][0] == pytest.approx(100.0, abs=0.3)
    assert beh.ended(a, None, 10.0) and a.speed == pytest.approx(5.0)


def test_synchronize_rushes_then_slows_to_arrive_at_its_final_speed():
    # From a standstill, 155 m in 10 s ending at 20 m/s needs more than 20 m/s on the way
    # (esmini's convex case: as NPC1 in esmini's synchronize.xosc, whose peak is 26.6 m/s).
    a, beh, rows = _synchronized(0.0, 155.0, 20.0, 20.0, 200.0, 12.0)
    arrived = int(np.argmax(rows[:, 1] >= 155.0))
    assert rows[arrived, 0] == pytest.approx(10.0, abs=0.05)
    assert rows[arrived, 3] == pytest.approx(20.0, abs=0.05)
    assert rows[:, 3].max() == pytest.approx(26.6, abs=0.3)
    assert a.speed == pytest.approx(20.0)


def test_synchronize_stops_and_waits_when_the_master_is_far():
    # 20 m to cover in the master's 30 s, at 5 m/s in the end, from 10 m/s: even slowing at
    # once would pass the point too early, so it stops, waits, and starts again.
    a, beh, rows = _synchronized(10.0, 20.0, 5.0, 5.0, 150.0, 31.0)
    stopped = rows[rows[:, 3] == 0.0, 0]
    assert len(stopped) and stopped[-1] - stopped[0] > 10.0
    arrived = int(np.argmax(rows[:, 1] >= 20.0))
    assert rows[arrived, 0] == pytest.approx(30.0, abs=0.1)
    assert rows[arrived, 3] == pytest.approx(5.0, abs=0.1)
    assert rows[:, 1].min() >= 0.0 and np.all(np.diff(rows[:, 1]) >= 0.0)


@pytest.mark.parametrize("final", [None, 5.0])
def test_synchronize_ends_within_the_master_tolerance(final):
    # The master at 10 m/s from s = 0 is within 5 m of s = 100 m from 9.5 s on.
    car = agent("car", s=0.0, lane=-1, speed=10.0)
    world = LiveWorld(car)
    a = agent(s=0.0, speed=10.0)
    settings = {"final_speed": final} if final is not None else {}
    beh = start("synchronize", a, world, master="car", master_at=100.0, target_s=80.0, master_tolerance=5.0,
                **settings)
    t = 0.0
    while not beh.ended(a, world, t):
        advance(a, beh.accel(a, world, t), t, DT)
        advance(car, 0.0, t, DT)
        t += DT
    assert t == pytest.approx(9.5, abs=0.02)


class ProjectingWorld(LiveWorld):
    """World coordinates are road coordinates shifted by (100, 0)."""

    def road_coords(self, agent, x, y):
        return x - 100.0, y


def test_trajectory_meets_its_waypoints_at_their_times():
    a = agent(s=50.0, lane=-1, speed=10.0)
    points = [(70.0, -1.75), (100.0, -5.25), (130.0, -5.25)]
    beh = start("trajectory", a, LiveWorld(), 1.0, s=[p[0] for p in points], t=[p[1] for p in points],
                times=[2.0, 5.0, 8.0])
    rows = simulate(a, beh, LiveWorld(), 9.0, t0=1.0)
    for (s, t), when in zip(points, [3.0, 6.0, 9.0]):
        k = int(round((when - 1.0) / DT))
        pos = (rows[k, 1], rows[k, 2]) if k < len(rows) else (a.s, a.t)
        assert math.hypot(pos[0] - s, pos[1] - t) < 0.1
    # The body turns with the path: heading towards the second waypoint while on it.
    assert rows[int(round(3.5 / DT)), 4] == pytest.approx(math.atan2(-3.5, 30.0), abs=1e-3)


def test_trajectory_in_world_coordinates_at_a_speed_then_on_along_the_road():
    a = agent(s=95.0, lane=-1, speed=8.0)
    world = ProjectingWorld()
    beh = start("trajectory", a, world, x=[210.0, 230.0], y=[-3.0, -1.75], speed=8.0)
    rows = simulate(a, beh, world, 6.0)
    on = rows[np.argmin(np.hypot(rows[:, 1] - 110.0, rows[:, 2] + 3.0))]
    assert math.hypot(on[1] - 110.0, on[2] + 3.0) < 0.1
    assert a.t == pytest.approx(-1.75, abs=0.05) and a.heading_rel == 0.0
    assert a.speed == pytest.approx(8.0)
