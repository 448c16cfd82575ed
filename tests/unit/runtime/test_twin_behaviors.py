"""Traffic behaviours as pure road-frame kinematics, against a small fake world."""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from addt_dsl.registry import BEHAVIORS
from addt_dsl.runtime.behaviors import AgentState, advance, lateral_profile, relative_heading
from addt_dsl.runtime.neighbours import Member

DT = 0.01
LANES = {-1: -1.75, -2: -5.25, 1: 1.75}  # centre t of each lane


class FakeWorld:
    """Straight road, lanes as above, band t in [-7, 3.5]; other actors by name."""

    dt = DT

    def __init__(self, *others: AgentState):
        self.others = {o.name: o for o in others}

    def lane_t(self, road, lane, s):
        return LANES.get(lane, math.nan)

    def lane_moves(self, road, lane):
        return False

    def road_band_t(self, road, s):
        return -7.0, 3.5

    def from_road_coords(self, agent, s, t):
        return s, t  # a road driven along +s: its frame is the agent's

    def occupants(self, road):
        for o in self.others.values():
            yield Member(o.name, road, o.s, o.t, o.speed, o.length_m)

    def actor_station(self, name):
        o = self.others.get(name)
        return None if o is None else (o.s, o.speed, o.length_m)

    def leader_of(self, agent):
        ahead = [(o.s - agent.s - 0.5 * (o.length_m + agent.length_m), o.speed)
                 for o in self.others.values() if o.s > agent.s and abs(o.t - agent.t) < 1.8]
        return min(ahead) if ahead else None


def agent(name="a", s=0.0, lane=-2, speed=10.0, length=4.6, width=1.9) -> AgentState:
    t = LANES[lane]
    return AgentState(name, "r", s, t, speed, 0.0, length, width, lane, t)


def start(keyword: str, a: AgentState, world, time_s: float = 0.0, **settings):
    beh = BEHAVIORS.implementation(keyword)(settings)
    beh.start(a, world, time_s)
    return beh


def simulate(a: AgentState, beh, world, seconds: float, t0: float = 0.0, others=()):
    t = t0
    rows = []
    for _ in range(int(round(seconds / DT))):
        rows.append((t, a.s, a.t, a.speed, relative_heading(a, t, DT)))
        acc = beh.accel(a, world, t) if beh.channel == "longitudinal" else 0.0
        advance(a, acc, t, DT)
        for o in others:
            advance(o, 0.0, t, DT)
        t += DT
    return np.array(rows)


@given(st.floats(-5.0, 5.0), st.floats(-5.0, 5.0), st.floats(0.5, 10.0))
def test_quintic_profile_starts_and_ends_at_rest(t_start, t_target, duration):
    a = agent()
    a.t_start, a.t_target, a.lc_start_s, a.lc_duration_s = t_start, t_target, 1.0, duration
    assert lateral_profile(a, 1.0) == pytest.approx(t_start)
    assert lateral_profile(a, 1.0 + duration) == pytest.approx(t_target)
    h = 1e-4 * duration
    # Zero lateral speed at both ends; monotone in between.
    for edge in (1.0 + h, 1.0 + duration - h):
        rate = (lateral_profile(a, edge + h) - lateral_profile(a, edge - h)) / (2 * h)
        assert abs(rate) < 1e-3 * (abs(t_target - t_start) + 1e-9) / duration * 100
    ts = [lateral_profile(a, 1.0 + u * duration) for u in np.linspace(0, 1, 50)]
    assert np.all(np.diff(ts) * np.sign(t_target - t_start) >= -1e-12)


def test_cruise_reaches_its_speed_within_comfort_limits():
    a = agent(speed=5.0)
    rows = simulate(a, start("cruise", a, FakeWorld(), speed=15.0, accel=2.0, decel=3.0), FakeWorld(), 10.0)
    assert a.speed == pytest.approx(15.0, abs=0.05)
    assert np.diff(rows[:, 3]).max() <= 2.0 * DT + 1e-12


def test_idm_keeps_a_safe_gap_behind_a_slow_leader():
    lead = agent("lead", s=40.0, speed=8.0)
    world = FakeWorld(lead)
    a = agent(speed=20.0)
    beh = start("idm", a, world, speed=25.0, time_gap=1.5, min_gap=2.0)
    simulate(a, beh, world, 40.0, others=[lead])
    gap = lead.s - a.s - 4.6
    assert a.speed == pytest.approx(8.0, abs=0.2)
    assert gap == pytest.approx(2.0 + 8.0 * 1.5, rel=0.15)


def test_sudden_brake_decelerates_at_its_rate_and_stops():
    a = agent(speed=20.0)
    rows = simulate(a, start("brake", a, FakeWorld(), decel=6.0, to_speed=0.0), FakeWorld(), 5.0)
    assert rows[1, 3] - rows[0, 3] == pytest.approx(-6.0 * DT)
    assert a.speed == 0.0


def test_lane_change_is_smooth_and_ends_in_the_target_lane():
    a = agent(lane=-2)
    world = FakeWorld()
    start("lane_change", a, world, to=-1, duration=4.0)
    rows = simulate(a, BEHAVIORS.implementation("cruise")({"speed": 10.0}), world, 6.0)
    assert a.t == pytest.approx(LANES[-1]) and a.lane == -1
    heading = rows[:, 4]
    assert heading.max() > 0.05 and np.abs(np.diff(heading)).max() < 0.01  # no jumps


@pytest.mark.parametrize("shape, factor", [("sinusoidal", math.pi ** 2 / 2), ("cubic", 6.0), ("linear", 6.0),
                                           ("quintic", 10.0 / math.sqrt(3.0))])
def test_lane_offset_takes_the_time_its_peak_lateral_acceleration_allows(shape, factor):
    # esmini's LaneOffsetAction: the time of an 8 m move at 3.5 m/s^2 is pi sqrt(8 / 7) s
    # (3.359 s) sinusoidal, sqrt(6 * 8 / 3.5) s cubic (and linear); from where the move starts.
    a = agent(lane=-1, speed=20.0)
    a.t = a.t_target = LANES[-1] + 0.5  # already 0.5 m left of its lane's centre
    world = FakeWorld()
    beh = start("lane_offset", a, world, time_s=1.0, to=-7.5, max_lat_accel=3.5, shape=shape)
    duration = math.sqrt(factor * 8.0 / 3.5)
    assert a.lc_duration_s == pytest.approx(duration)
    assert not beh.ended(a, world, 1.0 + duration - 0.01) and beh.ended(a, world, 1.0 + duration)
    rows = simulate(a, BEHAVIORS.implementation("cruise")({"speed": 20.0}), world, duration + 1.0, t0=1.0)
    assert a.t == pytest.approx(LANES[-1] - 7.5) and a.lane == -1
    if shape != "linear":  # (a linear blend's acceleration is unbounded at its ends)
        lat = rows[:, 2]
        peak = np.abs(np.diff(lat, 2)).max() / DT ** 2
        assert peak == pytest.approx(3.5, rel=0.02)


def test_lane_offset_keeps_the_station_moving_at_the_full_speed():
    # esmini moves a lane offset sideways without taking from the progress along the road
    # (a lane change's sideways part comes out of its step).
    a, b = agent(lane=-1, speed=20.0), agent(lane=-2, speed=20.0)
    world = FakeWorld()
    start("lane_offset", a, world, to=3.0, duration=2.0, shape="sinusoidal")
    start("lane_change", b, world, to=-1, duration=2.0, shape="sinusoidal")
    cruise = BEHAVIORS.implementation("cruise")
    simulate(a, cruise({"speed": 20.0}), world, 3.0)
    simulate(b, cruise({"speed": 20.0}), world, 3.0)
    assert a.s == pytest.approx(60.0) and b.s < 60.0 - 0.1


def test_lane_offset_after_a_lane_change_counts_from_the_new_lane():
    a = agent(lane=-2)
    world = FakeWorld()
    start("lane_change", a, world, to=-1, duration=1.0)
    cruise = BEHAVIORS.implementation("cruise")({"speed": 10.0})
    simulate(a, cruise, world, 1.5)
    start("lane_offset", a, world, time_s=1.5, to=1.0, duration=1.0, shape="cubic")
    simulate(a, cruise, world, 2.0, t0=1.5)
    assert a.t == pytest.approx(LANES[-1] + 1.0)


def test_overtake_pulls_out_passes_and_returns():
    slow = agent("slow", s=30.0, lane=-2, speed=8.0)
    world = FakeWorld(slow)
    a = agent(s=0.0, lane=-2, speed=12.0)
    beh = start("overtake", a, world, speed=16.0, margin=8.0, duration=3.0)
    assert beh.target == "slow" and a.lane == -1  # pulled out towards the passing lane
    rows = simulate(a, beh, world, 25.0, others=[slow])
    assert beh.phase == "done" and a.lane == -2
    assert a.t == pytest.approx(LANES[-2])
    assert a.s - slow.s > 8.0 + 4.6
    # It was in the passing lane while level with the slow car.
    level = np.abs(rows[:, 1] - (30.0 + 8.0 * rows[:, 0])) < 4.6
    assert np.all(rows[level, 2] > LANES[-2] + 2.5)
    assert a.speed == pytest.approx(16.0, abs=0.05)


def test_overtake_without_a_passing_lane_just_holds_speed():
    a = agent(lane=1)
    a.t = a.t_target = LANES[1]
    beh = start("overtake", a, FakeWorld(), speed=12.0)  # agents drive +s: lane 2, which does not exist
    assert beh.phase == "done" and a.lane == 1 and a.lc_duration_s == 0.0


def test_walk_moves_at_a_heading_relative_to_the_road():
    a = agent(speed=0.0, length=0.5, width=0.5)
    beh = start("walk", a, FakeWorld(), speed=1.4, heading=math.radians(90.0))
    rows = simulate(a, beh, FakeWorld(), 6.0)
    assert a.speed == pytest.approx(1.4, abs=0.01)
    assert np.diff(rows[:, 3]).max() <= 1.0 * DT + 1e-12  # accel limit
    assert a.s == pytest.approx(0.0, abs=1e-9)
    speeds = np.append(rows[1:, 3], a.speed)
    assert a.t - LANES[-2] == pytest.approx(speeds.sum() * DT, rel=1e-9)
    assert rows[-1, 4] == pytest.approx(math.pi / 2)


def test_walk_ends_after_its_distance_or_its_time_and_walks_on():
    # As CARLA ScenarioRunner completes a speed action on a walker: after a distance (in a
    # straight line from where it started) or a time; the walker keeps its speed.
    heading = math.radians(30.0)
    a = agent(speed=0.0, length=0.5, width=0.5)
    beh = start("walk", a, FakeWorld(), speed=2.0, heading=heading, accel=1000.0, decel=1000.0, distance=1.5)
    ends = []
    for i in range(200):
        t = i * DT
        ends.append(beh.ended(a, FakeWorld(), t))
        advance(a, beh.accel(a, FakeWorld(), t), t, DT)
    first = ends.index(True)
    assert all(ends[first:]) and first == 75  # 1.5 m at 2 m/s: 0.75 s (the speed at once)
    assert a.speed == 2.0 and math.hypot(a.s, a.t - LANES[-2]) == pytest.approx(4.0, abs=1e-9)
    assert math.atan2(a.t - LANES[-2], a.s) == pytest.approx(heading, abs=1e-12)
    timed = start("walk", agent(speed=2.0), FakeWorld(), time_s=3.0, duration=10.0)
    assert not timed.ended(a, FakeWorld(), 12.99) and timed.ended(a, FakeWorld(), 13.0)
    endless = start("walk", agent(speed=2.0), FakeWorld())
    assert not endless.ended(a, FakeWorld(), 1e6)


def test_walk_stops_at_its_decel():
    a = agent(speed=2.0, length=0.5, width=0.5)
    beh = start("walk", a, FakeWorld(), speed=0.0, heading=math.radians(90.0), decel=1000.0)
    simulate(a, beh, FakeWorld(), 0.01)
    assert a.speed == 0.0
    b = agent(speed=2.0, length=0.5, width=0.5)
    rows = simulate(b, start("walk", b, FakeWorld(), speed=0.0, heading=0.5), FakeWorld(), 0.5)
    assert np.diff(rows[:, 3]).min() == pytest.approx(-3.0 * DT)  # the default: 3 m/s^2


@pytest.mark.parametrize("direction,edge", [("left", 3.5), ("right", -7.0)])
def test_cross_walks_over_the_road_and_stops_beyond_the_edge(direction, edge):
    a = agent(lane=-1, speed=0.0, length=0.5, width=0.5)
    beh = start("cross", a, FakeWorld(), speed=1.4, direction=direction, beyond=1.0)
    simulate(a, beh, FakeWorld(), 20.0)
    stop = edge + (1.0 if direction == "left" else -1.0)
    assert a.speed < 1e-3
    assert a.t == pytest.approx(stop, abs=0.05)


@pytest.mark.parametrize("shape", ["linear", "cubic", "sinusoidal"])
def test_cruise_over_a_distance_takes_its_time_from_the_speed_at_the_start(shape):
    # 60 m from 25 m/s to 15 m/s: 2 * 60 / (25 + 15) = 3 s (esmini's LongSpeedAction::Start),
    # the same for every symmetric shape; the mean speed 20 m/s covers the 60 m.
    a = agent(speed=25.0)
    beh = start("cruise", a, FakeWorld(), speed=15.0, distance=60.0, shape=shape)
    rows = simulate(a, beh, FakeWorld(), 4.0)
    at_3 = int(round(3.0 / DT))
    assert rows[at_3 - 20, 3] > 15.05 and rows[at_3 + 1, 3] == pytest.approx(15.0, abs=1e-9)
    assert rows[at_3 + 1, 1] - rows[0, 1] == pytest.approx(60.0, abs=0.2)
    assert not beh.ended(a, FakeWorld(), 2.9) and beh.ended(a, FakeWorld(), 3.0)


def test_cruise_over_a_distance_is_stretched_to_max_decel_and_is_at_once_without_a_change():
    # Linear 25 -> 15 m/s in 3 s is 10/3 m/s^2: max_decel 2 m/s^2 makes it 5 s (esmini's SetMaxRate).
    a = agent(speed=25.0)
    rows = simulate(a, start("cruise", a, FakeWorld(), speed=15.0, distance=60.0, max_decel=2.0), FakeWorld(), 6.0)
    assert np.diff(rows[:, 3]).min() == pytest.approx(-2.0 * DT, abs=1e-9)
    assert rows[int(round(4.9 / DT)), 3] > 15.1 and a.speed == pytest.approx(15.0, abs=1e-9)
    b = agent(speed=15.0)
    beh = start("cruise", b, FakeWorld(), speed=15.0, distance=60.0)
    assert beh.ended(b, FakeWorld(), DT)


def test_cruise_at_a_rate_goes_either_way_within_max_accel():
    # At 8 m/s^2 toward the target whichever way; speeding up, max_accel 5 m/s^2 bounds it.
    up, down = agent(speed=25.0), agent(speed=25.0)
    rows_up = simulate(up, start("cruise", up, FakeWorld(), speed=30.0, accel=8.0, decel=8.0, max_accel=5.0),
                       FakeWorld(), 2.0)
    rows_down = simulate(down, start("cruise", down, FakeWorld(), speed=17.0, accel=8.0, decel=8.0, max_accel=5.0),
                         FakeWorld(), 2.0)
    assert rows_up[int(round(0.5 / DT)), 3] == pytest.approx(27.5, abs=1e-6) and up.speed == pytest.approx(30.0)
    assert rows_down[int(round(0.5 / DT)), 3] == pytest.approx(21.0, abs=1e-6) and down.speed == pytest.approx(17.0)
