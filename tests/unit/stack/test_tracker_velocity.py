"""The tracker estimates velocity for detectors that measure none (learned perception)."""

import math

import numpy as np

from addt_dsl.stack.nodes import Obj, Tracker

NO_FAULT = staticmethod(lambda site, value: value)


def _det(x, y, vx=math.nan, vy=math.nan):
    return Obj(x, y, 0.0, vx, vy, 4.6, 1.9)


def test_second_sighting_initialises_velocity_then_it_is_smoothed():
    tr = Tracker()
    tr.update([_det(10.0, 0.0)], 0.0, lambda s, v: v)
    (o,) = tr.objects_at(0.05)
    assert (o.x, o.vx) == (10.0, 0.0)  # not measured yet: reported as standing still
    tr.update([_det(12.5, 0.0)], 0.1, lambda s, v: v)  # 25 m/s: beyond the normal 4 m gate
    (o,) = tr.objects_at(0.1)
    assert math.isclose(o.vx, 25.0) and o.vy == 0.0
    tr.update([_det(15.2, 0.0)], 0.2, lambda s, v: v)  # measured 27 m/s
    (o,) = tr.objects_at(0.2)
    assert math.isclose(o.vx, 25.0 + Tracker.velocity_gain * 2.0)


def test_noisy_positions_give_a_steady_velocity():
    rng = np.random.default_rng(0)
    tr = Tracker()
    for k in range(60):
        t = 0.1 * k
        tr.update([_det(20.0 * t + rng.normal(0, 0.15), 3.5 + rng.normal(0, 0.15))], t, lambda s, v: v)
    (o,) = tr.objects_at(6.0)
    assert abs(o.vx - 20.0) < 1.5 and abs(o.vy) < 1.5


def test_measured_velocity_path_is_unchanged():
    tr = Tracker()
    tr.update([_det(0.0, 0.0, 10.0, 0.0)], 0.0, lambda s, v: v)
    tr.update([_det(1.2, 0.0, 10.0, 0.0)], 0.1, lambda s, v: v)
    (o,) = tr.objects_at(0.1)
    assert math.isclose(o.vx, 0.5 * 10.0 + 0.5 * 12.0)
    # An uninitialised-velocity gate does not apply to tracks with a velocity.
    tr.update([_det(8.0, 0.0, 10.0, 0.0)], 0.2, lambda s, v: v)
    assert len(tr.objects_at(0.2)) == 2


def test_the_class_bounds_the_first_association_and_is_kept():
    # A new track has no velocity: its next detection may be as far as the class can move.
    def second_sighting(kind):
        tr = Tracker()
        tr.update([Obj(10.0, 0.0, 0.0, math.nan, math.nan, 0.5, 0.5, kind=kind)], 0.0, lambda s, v: v)
        tr.update([Obj(15.0, 0.0, 0.0, math.nan, math.nan, 0.5, 0.5, kind=kind)], 0.1, lambda s, v: v)
        return tr.objects_at(0.1)

    car = second_sighting("car")  # 5 m in 0.1 s: within 4 m + 45 m/s * 0.1 s, one track
    assert len(car) == 1 and math.isclose(car[0].vx, 50.0) and car[0].kind == "car"
    walkers = second_sighting("pedestrian")  # no walker moves 5 m in 0.1 s: a second object
    assert len(walkers) == 2 and {o.kind for o in walkers} == {"pedestrian"}
    assert all(o.vx == 0.0 for o in walkers)


def test_a_weak_detection_is_confirmed_by_a_second_sighting_in_a_row():
    """A detection from fewer returns than `min_hits` (weak) makes a weak track; seen again
    in the next frame it is confirmed; a weak sighting after a missed frame is not."""
    def weak(x):
        return Obj(x, 0.0, 0.0, 1.0, 0.0, 0.5, 0.5, weak=True)

    tr = Tracker()
    tr.update([weak(30.0)], 0.0, NO_FAULT)
    assert [o.weak for o in tr.objects_at(0.05)] == [True]
    tr.update([weak(30.1)], 0.1, NO_FAULT)
    assert [o.weak for o in tr.objects_at(0.1)] == [False]
    tr.update([weak(30.2)], 0.2, NO_FAULT)  # confirmed stays confirmed
    assert [o.weak for o in tr.objects_at(0.2)] == [False]
    late = Tracker()
    late.update([weak(30.0)], 0.0, NO_FAULT)
    late.update([weak(30.2)], 0.2, NO_FAULT)  # a frame missed in between: still weak
    assert [o.weak for o in late.objects_at(0.2)] == [True]
    full = Tracker()
    full.update([Obj(30.0, 0.0, 0.0, 1.0, 0.0, 0.5, 0.5)], 0.0, NO_FAULT)  # min_hits returns: confirmed at once
    assert [o.weak for o in full.objects_at(0.0)] == [False]
