"""The planner's prediction of other road users: the tracker's acceleration estimate, braking
to a stop and setting off across the road over the horizon (`predict_travel`), and what the
candidates' collision check makes of them. Figures by hand in each test."""

import math

import pytest

from addt_dsl.plan import RoadPlan, SegmentPlan
from addt_dsl.road.roadspec import build_network
from addt_dsl.runtime.fastroad import FastRoad
from addt_dsl.stack.nodes import LatticePlanner, Obj, Tracker, predict_travel
from addt_dsl.vehicles import VEHICLES

CAR, CYCLIST = VEHICLES["car"], VEHICLES["cyclist"]
NO_FAULT = staticmethod(lambda site, value: value)


def _road() -> FastRoad:
    plan = RoadPlan(name="r", source="inline", segments=[SegmentPlan(kind="line", length_m=1000.0)], right_lanes=1)
    network = build_network([plan])["r"]
    return FastRoad(network.road(next(iter(network.roads))))


ROAD = _road()


@pytest.mark.parametrize("v, a, tau, cap, expected", [
    (20.0, 0.0, 5.0, math.inf, 100.0),  # constant velocity
    (20.0, -6.0, 2.0, math.inf, 28.0),  # braking: 40 - 12
    (20.0, -6.0, 5.0, math.inf, 400.0 / 12.0),  # stopped after 3.33 s: v^2 / 2a, no reversal
    (-20.0, 6.0, 5.0, math.inf, -400.0 / 12.0),  # the same coming the other way
    (0.0, 1.5, 2.0, 6.0, 3.0),  # setting off: a tau^2 / 2
    (0.0, 1.5, 5.0, 6.0, 12.0 + 6.0),  # at the 6 m/s cap after 4 s: 12 m, then 6 m/s for 1 s
    (0.0, -1.5, 5.0, 6.0, -18.0),  # setting off the other way
    (7.0, 1.5, 2.0, 6.0, 14.0),  # faster than the cap already: held
    (20.0, -math.inf, 1.0, math.inf, 0.0),  # a corrupted estimate: stops at once, not NaN
    (0.0, math.inf, 1.0, 6.0, 6.0),
])
def test_predict_travel_by_hand(v, a, tau, cap, expected):
    assert predict_travel(v, a, tau, cap) == pytest.approx(expected, abs=1e-9)


def _track(speeds, measured=True, dt=0.1):
    """The tracker's estimate of a car on x moving at `speeds` [m/s] per frame (positions
    integrated exactly; velocities measured where `measured`)."""
    tr, x = Tracker(position_noise_m=0.1), 0.0
    for k, v in enumerate(speeds):
        if k:
            x += 0.5 * (speeds[k - 1] + v) * dt
        det = Obj(x, 0.0, 0.0, v if measured else math.nan, 0.0 if measured else math.nan, 4.6, 1.9, kind="car")
        tr.update([det], k * dt, lambda site, value: value)
    (o,) = tr.objects_at((len(speeds) - 1) * dt)
    return o


def test_tracker_estimates_a_measured_braking_and_none_from_positions_alone():
    braking = [20.0] * 10 + [20.0 - 4.0 * 0.1 * k for k in range(1, 11)]  # 4 m/s^2 for 1 s
    o = _track(braking)
    assert o.ax == pytest.approx(-4.0, abs=0.3) and abs(o.ay) < 1e-6
    steady = _track([20.0] * 20)
    assert abs(steady.ax) < 0.05  # within the planner's 0.5 m/s^2 noise floor
    # From positions alone (a detector without velocity): no estimate.
    assert _track(braking, measured=False).ax == 0.0


def test_tracker_acceleration_follows_a_step_within_three_updates():
    o = _track([20.0] * 10 + [19.6, 19.2, 18.8])
    # gain 0.5 per update on the filtered velocity's change: at least 1 - 0.5^3 = 87.5 % of a
    # step, less the filter's own lag on the velocity (measured at 0.1 m/s)
    assert -4.0 * 1.05 < o.ax < -4.0 * 0.75


def test_braking_lead_predicted_to_stop_rules_out_keeping_up_with_it():
    """Ego at 20 m/s, a lead 40 m ahead (centres) at 20 m/s braking at 6 m/s^2: constant
    velocity keeps the gap; braking, the lead stops 3.33 s later, 33.3 m on (s = 173.3 m),
    and the cruise candidate (to 25 m/s) is past 173 m within 3 s."""
    t = float(ROAD.lane_center_t(-1, 100.0))
    planner = LatticePlanner({"cruise_speed": 25.0})
    cv = [(140.0, t, 20.0, 0.0, CAR.length_m, CAR.width_m)]
    braking = [(*cv[0], -6.0, 0.0)]
    cost = lambda objs, speed: planner._cost(-1, t, speed, 100.0, t, 20.0, objs, -1, -1, 0.0)  # noqa: E731
    assert cost(cv, 25.0) < math.inf
    assert cost(braking, 25.0) == math.inf
    # Stopping at 6 m/s^2 takes 33.3 m: the ego stands at 133.3 m, the lead 173.3 m.
    assert cost(braking, 0.0) < math.inf
    # An acceleration under the noise floor, or the lead speeding up, is constant velocity.
    assert cost([(*cv[0], -0.4, 0.0)], 25.0) == cost(cv, 25.0)
    assert cost([(*cv[0], 2.0, 0.0)], 25.0) == cost(cv, 25.0)


def test_rider_turned_across_at_rest_is_predicted_setting_off_into_the_path():
    """junction_cyclist's 10 m trigger at the plan after the rider turns (9.02 s): ego at
    7.66 m/s, 6.33 m from the rider's box along the road (centres 8.93 m apart, less half of
    4.6 + 0.6), the rider's box 2.78 m across from the ego's centre with 2.15 m needed to miss
    (half of 1.8 + 1.9, + 0.3): it must come 0.63 m closer. Setting off at 1.5 m/s^2 it has
    at 0.92 s, while the ego (at 7.7 m/s) is within 2 m of its box along the road from 0.56 s
    to 1.73 s: every candidate meets it (stopping at 6 m/s^2 takes 4.89 m: 1.44 m left)."""
    t = float(ROAD.lane_center_t(-1, 100.0))
    planner = LatticePlanner({"cruise_speed": 8.0})
    rider = (100.0 + 8.93, t - 2.78, 0.0, 0.0, CYCLIST.width_m, CYCLIST.length_m)
    cost = lambda objs, speed: planner._cost(-1, t, speed, 100.0, t, 7.66, objs, -1, -1, 0.0)  # noqa: E731
    for speed in planner._speeds(7.66):
        assert cost([rider], speed) < math.inf  # at rest (constant velocity): it stays on the kerb
        assert cost([(*rider, 0.0, 1.5)], speed) == math.inf
    # Setting off away from the ego's path: nothing to meet.
    assert cost([(*rider, 0.0, -1.5)], 8.0) < math.inf


def test_walker_braking_across_stops_at_the_kerb_not_in_the_lane():
    """A walker 3 m beside the ego's centre walking towards it at 1.4 m/s but braking at
    2 m/s^2 stops after 0.49 m (v^2 / 2a): still 2.51 m away, beyond the 1.5 m reach (half of
    0.5 + 1.9, + 0.3); at constant velocity it walks into the path."""
    t = float(ROAD.lane_center_t(-1, 100.0))
    planner = LatticePlanner({"cruise_speed": 12.0})
    walker = (130.0, t - 3.0, 0.0, 1.4, 0.5, 0.5)
    cost = lambda objs: planner._cost(-1, t, 12.0, 100.0, t, 12.0, objs, -1, -1, 0.0)  # noqa: E731
    assert cost([walker]) == math.inf
    assert cost([(*walker, 0.0, -2.0)]) < math.inf
