"""The ego's dynamics over a batch (`vehicle.step` on sequences: one compiled call over the
runs): each state ends the same bit for bit as stepped alone, whatever its batch and place
in it, and as the kernel's Python source gives it; a NaN command is clamped (as numpy's
fmin / fmax clamp it), not carried into the state."""

import copy
import math

from hypothesis import given, settings
from hypothesis import strategies as st

import pytest

from addt_dsl.kernel import interpreted
from addt_dsl.runtime.vehicle import VehicleParams, VehicleState, step

DT = 0.01

car = st.tuples(st.floats(0.2, 1.2), st.floats(-3.0, 3.0), st.floats(0.0, 40.0))
command = st.tuples(st.floats(-0.7, 0.7), st.floats(-12.0, 6.0), st.sampled_from([0.0, 0.06, -0.04]))


@settings(max_examples=30, deadline=None)
@given(st.lists(car, min_size=1, max_size=9), st.lists(command, min_size=1, max_size=40), st.randoms())
def test_batch_equals_one_by_one(cars, commands, rnd):
    params = [VehicleParams.for_vehicle(mu=mu) for mu, _, _ in cars]
    batch = [VehicleState(0.0, 0.0, h, v) for _, h, v in cars]
    alone = copy.deepcopy(batch)
    for c in commands:
        # Each run its own command (rotated through the list), some at low speed, some fast.
        cs = [commands[(commands.index(c) + i) % len(commands)] for i in range(len(cars))]
        step(batch, params, [x[0] for x in cs], [x[1] for x in cs], DT, [x[2] for x in cs])
        for v, p, (steer, accel, grade) in zip(alone, params, cs):
            step(v, p, steer, accel, DT, grade)
    assert batch == alone
    order = list(range(len(cars)))
    rnd.shuffle(order)  # another order in the batch: the same states
    shuffled = [copy.deepcopy(batch[i]) for i in order]
    again = copy.deepcopy(batch)
    step(again, params, [0.1] * len(cars), [1.0] * len(cars), DT, [0.0] * len(cars))
    step(shuffled, [params[i] for i in order], [0.1] * len(cars), [1.0] * len(cars), DT, [0.0] * len(cars))
    assert [again[i] for i in order] == shuffled


@pytest.mark.parametrize("runs", [1, 3])
def test_nan_command_is_clamped_not_carried(runs):
    p = VehicleParams.for_vehicle()
    cars = [VehicleState(0.0, 0.0, 0.0, 20.0) for _ in range(runs)]
    step(cars, [p] * runs, [math.nan] * runs, [math.nan] * runs, DT, [0.0] * runs)
    for v in cars:
        assert all(math.isfinite(getattr(v, f)) for f in ("x", "y", "vx", "vy", "yaw_rate", "steer"))
        assert v.steer == p.steer_rate_rad_s * DT  # toward +max steer at the rate limit, as before


@settings(max_examples=25, deadline=None)
@given(st.lists(car, min_size=1, max_size=5), st.lists(command, min_size=1, max_size=12),
       st.sampled_from([0.01, 0.025, 0.004]))
def test_compiled_is_its_python(cars, commands, dt):
    params = [VehicleParams.for_vehicle(mu=mu) for mu, _, _ in cars]
    compiled = [VehicleState(0.0, 0.0, h, v) for _, h, v in cars]
    python = copy.deepcopy(compiled)
    for steer, accel, grade in commands + [(math.nan, math.nan, 0.0)]:
        n = len(cars)
        step(compiled, params, [steer] * n, [accel] * n, dt, [grade] * n)
        with interpreted():
            step(python, params, [steer] * n, [accel] * n, dt, [grade] * n)
    assert [repr(v) for v in compiled] == [repr(v) for v in python]
