"""The egos' states as one block (`vehicle.StateBlock`): each `VehicleState` a view of its
row (its attributes and the block agree both ways), a block's step of any of its rows the
same bits as `vehicle.step` of each state alone (whatever the rows stepped, their order and
their step lengths), its recorded rows and finite flags those of the attributes, and the
compiled kernels their Python's bits."""

import copy
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from addt_dsl.kernel import bits, interpreted
from addt_dsl.runtime.vehicle import N_STATE, STATE_FIELDS, StateBlock, VehicleParams, VehicleState, step, substeps

car = st.tuples(st.floats(0.2, 1.2), st.floats(-3.0, 3.0), st.floats(0.0, 40.0), st.sampled_from([0.01, 0.02, 0.025]))
command = st.tuples(st.floats(-0.7, 0.7), st.floats(-12.0, 6.0), st.sampled_from([0.0, 0.06, -0.04]))
# Where a recorded row puts x, y, heading, speed, accel, yaw rate, steer (`phases.FIELDS`' order).
COLUMNS = np.array([0, 1, 2, 3, 4, 5, 9])


def _cars(cars):
    return [VehicleState(float(i), 0.0, h, v) for i, (_, h, v, _) in enumerate(cars)]


@settings(max_examples=30, deadline=None)
@given(st.lists(car, min_size=1, max_size=7), st.lists(command, min_size=1, max_size=25), st.randoms())
def test_block_step_is_each_state_stepped_alone(cars, commands, rnd):
    params = [VehicleParams.for_vehicle(mu=mu) for mu, _, _, _ in cars]
    dts = [dt for _, _, _, dt in cars]
    blocked, alone = _cars(cars), _cars(cars)
    block = StateBlock(blocked, dts)
    for j, (steer, accel, grade) in enumerate(commands):
        # Some rows each step, in a shuffled order: the others stay as they are.
        rows = [i for i in range(len(cars)) if (i + j) % 3]
        rnd.shuffle(rows)
        assert block.step([(i, steer + 0.01 * i, accel, grade) for i in rows], [params[i] for i in rows],
                          rows) == [True] * len(rows)
        for i in rows:
            step(alone[i], params[i], steer + 0.01 * i, accel, dts[i], grade)
        assert blocked == alone
    assert bits(block.states) == bits(np.array([v.row for v in alone]))


def test_states_are_views_of_the_block_both_ways():
    cars = [VehicleState(1.0, 2.0, 0.3, 12.0, yaw_rate=0.1), VehicleState(5.0, -1.0, -0.2, 3.0, steer=0.05)]
    before = [v.values() for v in cars]
    block = StateBlock(cars, [0.01, 0.01])
    assert block.states.shape == (2, N_STATE) and block.states.tolist() == before  # copied in, in order
    assert all(np.shares_memory(v.row, block.states) for v in cars)
    cars[1].heading = 1.25  # an attribute write is the block's
    assert block.states[1, STATE_FIELDS.index("heading")] == 1.25
    block.states[0, STATE_FIELDS.index("vy")] = 4.0  # and the block's write the attribute's
    assert cars[0].vy == 4.0 and type(cars[0].vy) is float
    assert cars[0].speed == math.hypot(12.0, 4.0)
    for v in cars:  # every field reads its column
        assert [getattr(v, f) for f in STATE_FIELDS] == v.values()


def test_records_and_finite_are_the_attributes():
    cars = [VehicleState(1.0, 2.0, 0.3, 12.0, vy=0.7, accel=-1.5, yaw_rate=0.1, steer=0.02),
            VehicleState(math.nan, 0.0, 0.0, 1.0), VehicleState(0.0, 0.0, 0.0, math.inf),
            VehicleState(3.0, 4.0, 5.0, 6.0)]
    block = StateBlock(cars, [0.01] * 4)
    rows = [3, 0, 1]
    got = block.records(rows, COLUMNS, 10)
    for i, row in zip(rows, got):
        v = cars[i]
        want = [v.x, v.y, v.heading, v.speed, v.accel, v.yaw_rate, 0.0, 0.0, 0.0, v.steer]
        assert bits(np.array(row)) == bits(np.array(want))
    assert block.step([], [], rows) == [True, True, False]  # (nothing stepped)
    assert block.step([], [], [2, 3]) == [False, True]  # (another list of rows than the last)
    assert bits(block.states) == bits([v.values() for v in cars])


@settings(max_examples=20, deadline=None)
@given(st.lists(car, min_size=1, max_size=5), st.lists(command, min_size=1, max_size=10))
def test_compiled_is_its_python(cars, commands):
    params = [VehicleParams.for_vehicle(mu=mu) for mu, _, _, _ in cars]
    dts = [dt for _, _, _, dt in cars]
    compiled, python = StateBlock(_cars(cars), dts), StateBlock(_cars(cars), dts)
    rows = list(range(len(cars)))[::-1]
    for steer, accel, grade in commands + [(math.nan, math.nan, 0.0)]:
        inputs = [(i, steer, accel, grade) for i in rows]
        a = (compiled.step(inputs, [params[i] for i in rows], rows), compiled.records(rows, COLUMNS, 10))
        with interpreted():
            b = (python.step(inputs, [params[i] for i in rows], rows), python.records(rows, COLUMNS, 10))
        assert bits(compiled.states) == bits(python.states)
        assert a[0] == b[0] and bits(np.array(a[1])) == bits(np.array(b[1]))


def test_new_parameters_are_taken_up():
    """A run's parameters replaced (the road's friction changed): the block steps with the new ones."""
    low, high = VehicleParams.for_vehicle(mu=0.2), VehicleParams.for_vehicle(mu=1.0)
    blocked, alone = [VehicleState(0.0, 0.0, 0.0, 20.0)], [VehicleState(0.0, 0.0, 0.0, 20.0)]
    block = StateBlock(blocked, [0.01])
    for p in (high, high, low, low, high):
        block.step([(0, 0.4, -8.0, 0.0)], [p], [0])
        step(alone[0], p, 0.4, -8.0, 0.01, 0.0)
        assert blocked == alone


def test_vehicle_state_keeps_its_public_behaviour():
    v = VehicleState(1, 2.0, 0.5, 10.0, steer=0.1)
    assert v.x == 1.0 and v.vy == 0.0 and v.steer == 0.1 and v.pitch == 0.0
    assert repr(v).startswith("VehicleState(x=1.0, y=2.0, heading=0.5, vx=10.0, vy=0.0,")
    w = copy.deepcopy(v)
    assert w == v and w is not v and not np.shares_memory(w.row, v.row)
    w.x = 7.0
    assert v.x == 1.0 and w != v
    with pytest.raises(AttributeError):
        v.colour = "red"  # (no other attributes: a state is its row)
    assert (VehicleState(0.0, 0.0, 0.0, 1.0) == 3) is False


@pytest.mark.parametrize("dt,n", [(0.01, 1), (0.02, 2), (0.025, 3), (0.004, 1)])
def test_substeps(dt, n):
    count, h = substeps(dt)
    assert count == n and h == dt / n
