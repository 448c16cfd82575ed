"""The controllers of a batch in one kernel call (`ControlBlock.command`) give each
controller's own `Controller.command` bits (no fault sites), cycle after cycle, on mixed
roads, odd values included; a controller whose cycle raises gets that exception and leaves
its row as it was, the others their commands."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from addt_dsl.kernel import bits, interpreted
from addt_dsl.plan import SegmentPlan
from addt_dsl.stack.control import FIELDS, PERIOD, S_START, ControlBlock, Controller
from addt_dsl.stack.nodes import EgoBody, Plan
from tests.unit.stack.roadkit import STRAIGHT, road

BEND = road(SegmentPlan(kind="line", length_m=100.0),
            SegmentPlan(kind="arc", length_m=150.0, curvature_per_m=0.01),
            SegmentPlan(kind="line", length_m=100.0))
ROADS = (STRAIGHT, BEND)

odd = st.sampled_from([math.nan, math.inf, -math.inf, 0.0, -0.0])
plans = st.builds(lambda t_target, speed, s_start, t_start, length, brake:
                  Plan(-1, t_target, speed, s_start, t_start, length, 0.0, brake),
                  st.floats(-6.0, 6.0), st.one_of(st.floats(0.0, 40.0), odd), st.floats(0.0, 300.0),
                  st.floats(-6.0, 6.0), st.one_of(st.floats(0.5, 120.0), st.sampled_from([0.0, math.nan])),
                  st.one_of(st.just(0.0), st.floats(0.0, 9.0)))
# The ego mostly near the plan's speed (a PID command not at its limits), sometimes anything.
slips = st.one_of(st.floats(-0.5, 0.5), st.floats(-40.0, 40.0), odd)
cycles = st.builds(lambda plan, x, y, h, slip: (plan, (x, y, h, plan.speed + slip)),
                   plans, st.floats(-20.0, 320.0), st.floats(-30.0, 30.0), st.one_of(st.floats(-1.0, 1.0), odd), slips)
controllers = st.tuples(st.sampled_from(ROADS), st.floats(0.2, 3.0), st.floats(0.0, 0.5), st.floats(0.5, 1.0),
                        st.sampled_from([0.01, 0.02]), st.lists(cycles, min_size=1, max_size=3))


def _make(gain, wn, mu, period) -> Controller:
    c = Controller({"kp": gain, "control_rate": 1.0 / period}, 2.7, EgoBody(mu=mu))
    c.lateral_wn = wn
    return c


def _outcome(fn):
    try:
        return tuple(bits(v) for v in fn())
    except Exception as exc:  # noqa: BLE001 - compared as outcomes
        return type(exc).__name__, str(exc)


def _run(cases):
    """Each controller's outcome per cycle and its row at the end, alone and in a block."""
    alone = [_make(*case[1:5]) for case in cases]
    batched = [_make(*case[1:5]) for case in cases]
    block = ControlBlock.holding(batched)
    assert ControlBlock.holding(batched) is block
    want: list[list] = [[] for _ in cases]
    got: list[list] = [[] for _ in cases]
    stopped: set[int] = set()
    hints = [0.0] * len(cases)
    for cycle in range(max(len(case[5]) for case in cases)):
        live = [i for i, case in enumerate(cases) if cycle < len(case[5]) and i not in stopped]
        if not live:
            break
        for i in live:
            road, c = cases[i][0], alone[i]
            plan, (x, y, h, v) = cases[i][5][cycle]

            def one(road=road, c=c, plan=plan, x=x, y=y, h=h, v=v, hint=hints[i]):
                s, t = road.project(x, y, hint)
                return c.command(plan, (x, y, h, v), road, float(s), float(t), float(c.row[PERIOD]), lambda _, val: val)

            want[i].append(_outcome(one))
            batched[i].follow(cases[i][5][cycle][0])
        out = block.command([batched[i] for i in live],
                            [(*cases[i][5][cycle][1], hints[i]) for i in live], [cases[i][0] for i in live])
        for i, x in zip(live, out):
            got[i].append((type(x).__name__, str(x)) if isinstance(x, Exception) else tuple(bits(v) for v in x))
            if isinstance(x, Exception):
                stopped.add(i)  # (a stack error stops its run)
            hints[i] = cases[i][5][cycle][1][0] % 300.0
    for i in stopped:  # the alone controller went on only as far as the batched one
        want[i] = want[i][:len(got[i])]
    state = slice(0, S_START)  # (gains and memory: the plan is the block's own input)
    return want, got, [bits(list(c.row[state])) for c in alone], [bits(list(c.row[state])) for c in batched], stopped


@settings(max_examples=60, deadline=None)
@given(st.lists(controllers, min_size=1, max_size=5))
def test_a_block_gives_each_controllers_own_bits_and_a_raising_row_stays_as_it_was(cases):
    for mode in ("compiled", "interpreted"):
        if mode == "interpreted":
            with interpreted():
                want, got, rows_alone, rows_block, stopped = _run(cases)
        else:
            want, got, rows_alone, rows_block, stopped = _run(cases)
        assert got == want
        for i in range(len(cases)):
            if i not in stopped:
                assert rows_block[i] == rows_alone[i]


def test_a_row_that_raises_is_its_own_outcome_and_keeps_its_state():
    ok, bad = _make(1.0, 1.0, 0.8, 0.01), _make(1.0, 1.0, 0.8, 0.01)
    block = ControlBlock([ok, bad])
    ok.follow(Plan(-1, -1.75, 20.0, 0.0, -1.75, 60.0, 0.0))
    bad.follow(Plan(-1, -1.75, 20.0, 0.0, -1.75, 0.0, 0.0))  # a lateral path of length 0: division by zero
    before = bits(list(bad.row))
    out = block.command([ok, bad], [(100.0, -1.75, 0.0, 19.0, 100.0)] * 2, [STRAIGHT, STRAIGHT])
    assert isinstance(out[1], ZeroDivisionError)
    assert bits(list(bad.row)) == before
    assert out[0][0] == 0.0 and out[0][1] > 0.0  # on its path, 1 m/s slow: straight on, speeding up
    assert ok.last_xy == (100.0, -1.75) and ok.integral == 1.0 * 0.01


def test_a_new_block_takes_the_rows_as_they_were():
    a, b = _make(1.5, 0.7, 0.8, 0.01), _make(0.5, 1.0, 0.8, 0.02)
    a.integral, b.last_xy = 2.5, (3.0, 4.0)
    rows = [list(a.row), list(b.row)]
    block = ControlBlock.holding([a, b])
    assert block.rows.shape == (2, FIELDS)
    assert [list(a.row), list(b.row)] == rows
    assert np.shares_memory(a.row, block.rows) and b.last_xy == (3.0, 4.0) and a.kp == 1.5
