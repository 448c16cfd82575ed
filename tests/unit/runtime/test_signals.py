"""Signals derived from a trace: the ones that need the run's past."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from addt_dsl.registry import SIGNALS
from addt_dsl.runtime.signals import time_to_overlap
from addt_dsl.runtime.world import box_separation
from addt_dsl.runtime.trace import ActorTrack


def _track(x, y):
    n = len(x)
    zeros = np.zeros(n)
    return ActorTrack("ego", 4.5, 1.9, np.asarray(x, float), np.asarray(y, float), *[zeros] * 9)


class _Trace:
    def __init__(self, track):
        self.actors = {"ego": track}


def test_travelled_sums_the_path_not_the_displacement():
    # Out 3 m east, 4 m north, and back to the start: 14 m travelled, 0 m away.
    track = _track([0, 3, 3, 3, 0], [0, 0, 4, 0, 0])
    got = SIGNALS.implementation("travelled").compute(_Trace(track), ("ego",))
    assert got == pytest.approx([0, 3, 7, 11, 14])


def test_signals_of_the_past_are_marked_so_that_triggers_refuse_them():
    assert SIGNALS.get("travelled").history and SIGNALS.get("jerk").history
    assert not SIGNALS.get("speed").history and not SIGNALS.get("gap").history


def _mover(name, x, y, heading, speed, frame, length=4.0, width=2.0):
    x, y = np.asarray(x, float), np.asarray(y, float)
    n = len(x)
    zeros = np.zeros(n)
    return ActorTrack(name, length, width, x, y, np.full(n, heading), np.full(n, speed), *[zeros] * 7, frame=frame)


def _ttc(a, b):
    class _T:
        actors = {a.name: a, b.name: b}
        period_s = 0.1
    return SIGNALS.implementation("ttc").compute(_T(), (a.name, b.name))


def test_ttc_of_an_oncoming_car_passing_a_stopped_ego_is_never_a_collision():
    # The ego stands at the origin; an oncoming car (another frame: it drives the other way)
    # passes at y = 4 m: 4 - 1 - 1 = 2 m of lateral clearance between the boxes. The
    # Euclidean-gap rate reached 0 s as it went by; the boxes never meet: capped (99 s).
    xs = np.arange(40.0, -40.0, -1.0)
    ego = _mover("ego", np.zeros_like(xs), np.zeros_like(xs), 0.0, 0.0, "r1")
    car = _mover("car", xs, np.full_like(xs, 4.0), np.pi, 10.0, "r1~")
    assert np.all(_ttc(ego, car) == 99.0)


def test_ttc_head_on_on_different_frames_is_the_gap_over_the_closing_speed():
    # Centres 50 m apart, both 4 m long, 10 m/s each towards the other: 46 m / 20 m/s.
    ego = _mover("ego", [0.0], [0.0], 0.0, 10.0, "r1")
    car = _mover("car", [50.0], [0.0], np.pi, 10.0, "r1~")
    assert _ttc(ego, car) == pytest.approx([2.3])
    # Crossing: a stopped ego, a car coming up from the south on x = 0 at 5 m/s: its front
    # (centre - 2 m) meets the ego's side (y = -1 m) once its centre is at y = -3 m: 17 m / 5 m/s.
    car = _mover("car", [0.0], [-20.0], np.pi / 2, 5.0, "r2")
    assert _ttc(_mover("ego", [0.0], [0.0], 0.0, 0.0, "r1"), car) == pytest.approx([3.4])


@settings(max_examples=150, deadline=None)
@given(st.floats(-30, 30), st.floats(-30, 30), st.floats(-np.pi, np.pi), st.floats(0, 15),
       st.floats(-np.pi, np.pi), st.floats(0, 15))
def test_time_to_overlap_is_when_stepped_boxes_first_overlap(x, y, hb, vb, ha, va):
    """Against the boxes moved in 1 ms steps and tested with `world.box_separation`."""
    a = _mover("a", [0.0], [0.0], ha, va, "p")
    b = _mover("b", [x], [y], hb, vb, "q", length=4.5, width=1.8)
    got = float(time_to_overlap(a, b, 5.0)[0])
    want = 5.0
    for k in range(5001):
        t = k * 1e-3
        box_a = (va * np.cos(ha) * t, va * np.sin(ha) * t, ha, 4.0, 2.0)
        box_b = (x + vb * np.cos(hb) * t, y + vb * np.sin(hb) * t, hb, 4.5, 1.8)
        if box_separation(box_a, box_b) <= 0.0:
            want = t
            break
    assert got == pytest.approx(want, abs=2e-3) or (want == 5.0 and got >= 4.998)


def test_lon_gap_projects_both_boxes_on_the_first_actors_heading():
    # A 4 x 2 m car at the origin heading 30 deg; a 0.6 x 0.5 m walker crossing (heading
    # 120 deg: its box reaches 0.25 m along the car's heading) 10 m ahead and 3 m to the
    # side: 10 - 0.25 - 2 = 7.75 m; 10 m behind (heading 30 deg, reaching 0.3 m):
    # -(10 - 0.3 - 2) = -7.7 m; beside the car, within its length: 0.
    h = np.radians(30.0)
    u, n = np.array([np.cos(h), np.sin(h)]), np.array([-np.sin(h), np.cos(h)])
    at = [10 * u + 3 * n, -10 * u, 1.0 * u + 4 * n]
    car = _mover("car", [0.0] * 3, [0.0] * 3, h, 10.0, "r1")
    walker = _mover("walker", [p[0] for p in at], [p[1] for p in at], 0.0, 1.5, "r2", length=0.6, width=0.5)
    walker.heading[:] = [h + np.pi / 2, h, h]

    class _T:
        actors = {"car": car, "walker": walker}
    got = SIGNALS.implementation("lon_gap").compute(_T(), ("car", "walker"))
    assert got == pytest.approx([7.75, -7.7, 0.0])
