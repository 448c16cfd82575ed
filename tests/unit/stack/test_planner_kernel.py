"""The lattice planner's candidate costs as a compiled kernel (`candidate_costs`): the
compiled form gives its Python source's bits, and both give the bits of the planner's
per-candidate loop as it was written before (`_loop_cost` below, kept as the reference),
over random candidates and objects, non-finite values included (a corrupted track's)."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from addt_dsl.kernel import bits
from addt_dsl.stack.nodes import EgoBody, LatticePlanner, _lane_steps, candidate_costs, objects_array, predict_travel


def _predict(v, a, tau, v_cap):
    if a == 0.0:
        return v * tau
    if a * v < 0.0:
        t_stop = -v / a
        if tau >= t_stop:
            return 0.5 * v * t_stop
        return v * tau + 0.5 * a * tau * tau
    if abs(v) >= v_cap:
        return v * tau
    top = math.copysign(v_cap, a)
    t_top = (top - v) / a
    if tau <= t_top:
        return v * tau + 0.5 * a * tau * tau
    return 0.5 * (v + top) * t_top + top * (tau - t_top)


def _loop_cost(self, lane, t_lane, speed, s0, t0, v0, objs, current, home, now) -> float:
    """`LatticePlanner._cost` as a Python loop over tuples (the code the kernel replaced)."""
    cost = 0.0
    s, v = s0, v0
    dt = self.dt_s
    steps = int(self.horizon_s / dt)
    brake = -self.brake_limit
    path = []
    for k in range(1, steps + 1):
        tk = k * dt
        a = (speed - v) / dt
        if not a < 2.0:
            a = 2.0
        elif not a > brake:
            a = brake
        v_next = v + a * dt
        if not v_next > 0.0:
            if a < 0.0:
                s += v * v / (-2.0 * a)
            v_next = 0.0
        else:
            s += 0.5 * (v + v_next) * dt
        v = v_next
        u = tk / 3.0
        if not u < 1.0:
            u = 1.0
        path.append((tk, s, t0 + (t_lane - t0) * (u * u * (3 - 2 * u)), v))
    ego_len, ego_wid = self.body.length_m, self.body.width_m
    for os_, ot, ov, ovt, olen, owid, *acc in objs:
        a_s, a_t = acc if acc else (0.0, 0.0)
        if not (a_s * ov < 0.0 and abs(a_s) >= self.PREDICT_ACCEL_MIN):
            a_s = 0.0
        if not abs(a_t) >= self.PREDICT_ACCEL_MIN:
            a_t = 0.0
        lat_reach = 0.5 * (owid + ego_wid) + 0.3
        half_len = 0.5 * (olen + ego_len)
        gap_low = -(olen + ego_len) - 2.0
        prev = os_ - s0 - half_len
        for tk, s, t, v in path:
            gap = os_ + _predict(ov, a_s, tk, math.inf) - s - half_len
            if abs(t - ot - _predict(ovt, a_t, tk, self.PREDICT_CROSS_SPEED)) < lat_reach:
                lo, hi = (prev, gap) if prev < gap else (gap, prev)
                if lo < 2.0 and hi > gap_low:
                    return math.inf
                if gap >= 0.0:
                    desired = max(5.0, self.time_gap * v)
                    if gap < desired:
                        cost += 4.0 * (desired - gap) / desired
            prev = gap
    cost += 1.0 * abs(self.cruise - speed) / max(self.cruise, 1.0) * 10.0
    if lane != current:
        cost += 1.5 + (3.0 if now - self.last_change_s < self.lane_change_cooldown_s else 0.0)
    if home is not None:
        cost += 2.5 * _lane_steps(lane, home)
    return cost


# Mostly plausible values (so candidates collide, follow and pass), some non-finite or -0.0.
odd = st.sampled_from([math.nan, math.inf, -math.inf, -0.0, 0.0, 1e300])
station = st.floats(60.0, 200.0) | odd
offset = st.sampled_from([-1.75, -5.25, 1.75]) | st.floats(-9.0, 2.0) | odd
velocity = st.sampled_from([0.0, 10.0, 20.0, 25.0]) | st.floats(-30.0, 40.0) | odd
accel = st.sampled_from([0.0, 0.3, -0.7, 2.0, -6.0]) | st.floats(-10.0, 10.0) | odd
size = st.floats(0.3, 12.0) | odd
objects = st.lists(st.tuples(station, offset, velocity, velocity | st.floats(-3.0, 3.0), size, size, accel, accel)
                   | st.tuples(station, offset, velocity, st.just(0.0), size, size), max_size=12)
lanes = st.sampled_from([-3, -2, -1, 1, 2])
candidates = st.lists(st.tuples(lanes, offset, st.sampled_from([0.0, 2.0, 25.0]) | velocity), min_size=1, max_size=9)
planners = st.builds(
    lambda cruise, gap, mu, length, change: _planner(cruise, gap, mu, length, change),
    st.sampled_from([25.0, 8.0, 0.5]), st.sampled_from([1.5, 0.0, 3.0]), st.sampled_from([0.8, 0.3]),
    st.sampled_from([4.7, 12.0]), st.sampled_from([-1e9, 1.0]))


def _planner(cruise, gap, mu, length, change) -> LatticePlanner:
    p = LatticePlanner({"cruise_speed": cruise, "time_gap": gap}, EgoBody(length_m=length, mu=mu))
    p.last_change_s = change
    return p


@settings(max_examples=300, deadline=None)
@given(planners, candidates, objects, st.floats(90.0, 110.0) | odd, offset, velocity, lanes,
       st.sampled_from([None, -1, -2, 1]))
def test_kernel_gives_the_python_loopsbits(planner, cands, objs, s0, t0, v0, current, home):
    args = planner._cost_args(s0, t0, v0, objects_array(objs), current, home, 2.0)
    lane_a = np.array([c[0] for c in cands], dtype=np.int64)
    t_a, v_a = np.array([c[1] for c in cands]), np.array([c[2] for c in cands])
    compiled, interpreted = np.empty(len(cands)), np.empty(len(cands))
    with np.errstate(all="ignore"):
        candidate_costs(lane_a, t_a, v_a, *args, compiled)
        candidate_costs.py_func(lane_a, t_a, v_a, *args, interpreted)
    reference = [_loop_cost(planner, lane, t, v, s0, t0, v0, objs, current, home, 2.0) for lane, t, v in cands]
    assert bits(compiled) == bits(interpreted) == bits(reference)
    # One candidate at a time (`_cost`) is the same.
    assert bits([planner._cost(lane, t, v, s0, t0, v0, objs, current, home, 2.0) for lane, t, v in cands]) \
        == bits(reference)


@settings(max_examples=200, deadline=None)
@given(velocity | st.floats(allow_nan=True), accel | st.floats(allow_nan=True), st.floats(0.0, 10.0) | odd,
       st.sampled_from([math.inf, 6.0, 0.0]))
def test_predict_travel_compiled_gives_its_pythonbits(v, a, tau, cap):
    with np.errstate(all="ignore"):
        assert bits([predict_travel(v, a, tau, cap)]) == bits([predict_travel.py_func(v, a, tau, cap)]) \
            == bits([_predict(v, a, tau, cap)])


def test_objects_array_pads_six_fields_with_no_acceleration():
    arr = objects_array([(1.0, 2.0, 3.0, 4.0, 5.0, 6.0), (1.0, 2.0, 3.0, 4.0, 5.0, 6.0, -3.0, 0.5)])
    assert arr.dtype == np.float64 and arr.shape == (2, 8)
    assert arr[0, 6:].tolist() == [0.0, 0.0] and arr[1, 6:].tolist() == [-3.0, 0.5]
    assert objects_array([]).shape == (0, 8)


def test_clearance_and_collision_by_hand():
    """Ego at s=100 m, 20 m/s, cruise 20 m/s, a straight candidate at 20 m/s (no speed
    change: s = 100 + 20 t at each of the 10 checks), objects as long as the ego (L) in its
    lane. A car 30 m ahead (centres) at 20 m/s: gap 30 - L under the desired 30 m at every
    check: 10 x 4 L / 30. One 60 m ahead: gap 60 - L, no cost. A standing one 30 m ahead:
    the boxes meet within the horizon: inf."""
    p = LatticePlanner({"cruise_speed": 20.0})
    length, width = p.body.length_m, p.body.width_m
    cost = lambda objs: p._cost(-1, 0.0, 20.0, 100.0, 0.0, 20.0, objs, -1, -1, 0.0)  # noqa: E731
    assert cost([(160.0, 0.0, 20.0, 0.0, length, width)]) == 0.0
    assert math.isclose(cost([(130.0, 0.0, 20.0, 0.0, length, width)]), 10 * 4.0 * length / 30.0, rel_tol=1e-12)
    assert cost([(160.0, 0.0, 20.0, 0.0, length, width), (130.0, 0.0, 0.0, 0.0, length, width)]) == math.inf
    # Beside the ego's path (3.5 m over, wider than half the widths + 0.3 m): no cost.
    assert cost([(130.0, 3.5, 0.0, 0.0, length, width)]) == 0.0


def test_kernel_gives_the_python_loops_bits_over_a_grid_of_scenes():
    """Every combination of a few plausible objects and candidates (dense where the random
    draws are sparse: an object standing, braking, setting off across, in the ego's path)."""
    objs = [(s, t, v, vt, 4.5, 1.8, a_s, a_t) for s in (80.0, 106.0, 115.0, 130.0, 160.0) for t in (-1.75, -5.25, -3.0)
            for v in (0.0, 10.0, 20.0, -15.0) for vt in (0.0, 1.2) for a_s in (0.0, -6.0, 2.0) for a_t in (0.0, -1.5)]
    cands = [(lane, t, v) for lane in (-1, -2) for t in (-1.75, -5.25, -2.6) for v in (0.0, 8.0, 25.0)]
    planner = LatticePlanner({"cruise_speed": 25.0})
    lane_a = np.array([c[0] for c in cands], dtype=np.int64)
    t_a, v_a = np.array([c[1] for c in cands]), np.array([c[2] for c in cands])
    for v0 in (0.0, 10.0, 27.0):
        for o in objs:
            args = planner._cost_args(100.0, -1.75, v0, objects_array([o]), -1, -1, 2.0)
            got = np.empty(len(cands))
            candidate_costs(lane_a, t_a, v_a, *args, got)
            want = [_loop_cost(planner, lane, t, v, 100.0, -1.75, v0, [o], -1, -1, 2.0) for lane, t, v in cands]
            assert bits(got) == bits(want), (v0, o)


def _old_overlap(a, b, c):
    if b == 0.0:
        return (-math.inf, math.inf) if abs(a) < c else (math.inf, -math.inf)
    t1, t2 = (-c - a) / b, (c - a) / b
    return (t1, t2) if t1 < t2 else (t2, t1)


def _loop_ttc(fcw, s0, t0, v_s, v_t, objs):
    """`ForwardCollisionCheck.time_to_collision` as a Python loop (the code the kernel replaced)."""
    half_len, half_wid = 0.5 * fcw.body.length_m, 0.5 * fcw.body.width_m
    best, closing = math.inf, 0.0
    for os_, ot, ovs, ovt, olen, owid, *_ in objs:
        d = os_ - s0
        if not d > 0.0:
            continue
        a0, a1 = _old_overlap(d, ovs - v_s, 0.5 * olen + half_len)
        l0, l1 = _old_overlap(ot - t0, ovt - v_t, 0.5 * owid + half_wid + fcw.lateral_margin_m)
        start = max(a0, l0, 0.0)
        if start <= min(a1, l1, fcw.horizon_s) and start < best:
            best, closing = start, v_s - ovs
    return best, closing


@settings(max_examples=300, deadline=None)
@given(objects, st.floats(90.0, 110.0) | odd, offset, velocity, st.sampled_from([0.0, 0.5, -1.0]) | velocity)
def test_first_collision_gives_the_python_loopsbits(objs, s0, t0, v_s, v_t):
    from addt_dsl.stack.nodes import ForwardCollisionCheck, first_collision

    fcw = ForwardCollisionCheck({})
    args = (s0, t0, v_s, v_t, objects_array(objs), 0.5 * fcw.body.length_m, 0.5 * fcw.body.width_m,
            fcw.lateral_margin_m, fcw.horizon_s)
    with np.errstate(all="ignore"):
        compiled, interpreted = first_collision(*args), first_collision.py_func(*args)
    assert bits(compiled) == bits(interpreted) == bits(_loop_ttc(fcw, s0, t0, v_s, v_t, objs)) \
        == bits(fcw.time_to_collision(s0, t0, v_s, v_t, objs))
