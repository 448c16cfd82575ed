"""A grid over a parameter without a range is checked wherever the parameter is used, over
all its values: `grid t_flip in [-1.5, 1e6] s` on a 10 s run passed `check`, its far cell
never injected and was recorded as a pass; `behind ego gap` with `grid gap in [1, 30] m`
put the actor below s = 0 where `at -20 m` is refused."""

from __future__ import annotations

import pytest

from addt_dsl.compiler import compile_source

BASE = """scenario axis {{
  duration 10 s
  step 50 ms
  road street {{
    line length 400 m
  }}
  param t_flip = 2 s
  param gap = 2 m
  ego car on street lane -1 at 10 m speed 14 m/s {{
    stack bev cruise_speed 15 m/s
  }}
  agent lead car {placement} speed 10 m/s {{
    slow: at t_flip + 1 s then behavior brake decel 2 m/s^2
  }}
  faults {{
    at t_flip bitflip control.steer count 1
  }}
  expect {{
    no collision
  }}
  sweep {{
    {grid}
  }}
}}
"""


def _codes(placement: str, grid: str) -> list[tuple[str, int]]:
    result = compile_source(BASE.format(placement=placement, grid=grid), path="axis.addt")
    return [(d.code, d.span.line) for d in result.diagnostics if d.severity == "error"]


@pytest.mark.parametrize("grid, expected", [
    ("grid t_flip in [-1.5, 1e6] s", [("E0302", 13), ("E0302", 16)]),  # a step's time, a fault's
    ("grid t_flip in [2, 9.5] s", [("E0302", 13)]),
    ("grid t_flip in [2, 10] s", [("E0302", 13)]),
    ("grid t_flip in [0, 9] s", []),
])
def test_a_grid_is_checked_over_all_its_values(grid, expected):
    assert _codes("on street lane -1 at 100 m", grid) == expected


@pytest.mark.parametrize("placement", ["behind ego gap", "on street lane -1 at 10 m + -1 * gap"])
def test_relative_and_absolute_placements_are_checked_alike(placement):
    # gap = 30 m puts the lead below s = 0 either way; the nominal 2 m does not (the shrinker goes back to it).
    assert _codes(placement, "grid gap in [1, 30] m") == [("E0301", 12)]
    assert _codes(placement.replace("gap", "30 m"), "grid t_flip in [1, 2] s") == [("E0301", 12)]
    assert _codes(placement, "grid gap in [1, 2] m") == []


# ---------------------------------------------------------------- constraints narrow ranges

SAMPLED_FAULT = """scenario s {{
  duration 10 s
  road r {{
    line length 400 m
  }}
  param t_s = 3 s in [1 s, 20 s]
{assume}
  ego car on r lane -1 at 20 m speed 10 m/s {{
    stack bev
    sensor lidar rate 10 Hz rays 360 range 80 m
  }}
  faults {{
    at t_s for 1 s drop lidar
  }}
  sweep {{ random 4 }}
}}
"""


@pytest.mark.parametrize("assume, codes", [
    ("", ["E0302"]),  # t_s can be 20 s: past the end
    ("  assume t_s <= 9 s", []),  # what the error's help asks for
    ("  assume 9 s >= t_s and t_s > 2 s", []),  # either way round, inside an `and`
    ("  assume t_s <= 15 s", ["E0302"]),  # still reaches past the end
    ("  assume t_s <= 9 s or t_s > 30 s", ["E0302"]),  # an `or` bounds nothing for sure
])
def test_a_constraint_that_excludes_the_bad_values_is_what_the_help_says(assume, codes):
    # The help of "can be outside" says: narrow the range, or add an `assume` that excludes
    # those values. An `assume` did not count: the check read the declared range only.
    result = compile_source(SAMPLED_FAULT.format(assume=assume), path="s.addt")
    assert [d.code for d in result.diagnostics if d.severity == "error"] == codes


def test_narrowed_ranges_is_sound_and_leaves_what_it_cannot_bound():
    from addt_dsl import expr as E
    from addt_dsl.compiler.exprs import narrowed_ranges

    p, q = E.Param(name="p"), E.Param(name="q")
    ranges = {"p": (0.0, 10.0), "q": (0.0, 10.0)}

    def cmp(op, left, right):
        return E.Binary(op=op, left=left, right=right)

    five = E.Binary(op="*", left=E.Num(value=2.0), right=E.Num(value=2.5))
    assert narrowed_ranges(ranges, [cmp("<", p, five)]) == {"p": (0.0, 5.0), "q": (0.0, 10.0)}
    assert narrowed_ranges(ranges, [cmp("<=", E.Num(value=3.0), q)]) == {"p": (0.0, 10.0), "q": (3.0, 10.0)}
    assert narrowed_ranges(ranges, [cmp("==", p, E.Num(value=4.0))])["p"] == (4.0, 4.0)
    assert narrowed_ranges(ranges, [cmp("<", p, q)]) == ranges  # relational: no constant bound
    assert narrowed_ranges(ranges, [cmp("<", p, E.Num(value=-1.0))]) == ranges  # never holds: reported elsewhere
    assert narrowed_ranges(ranges, [cmp("!=", p, E.Num(value=4.0))]) == ranges
