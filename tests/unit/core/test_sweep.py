import pytest

from addt_dsl.compiler import compile_source
from addt_dsl.sweep import UnsatisfiableAssumptions, expand

BASE = """
scenario s {{
  duration 5 s
  road r {{
    line length 300 m
  }}
  param v = 10 m/s in [5 m/s, 20 m/s]
  param gap = 30 m in [10 m, 50 m]
  {assume}
  ego car on r lane -1 at 10 m speed v
  agent lead car on r lane -1 at 10 m + gap speed 5 m/s
  expect {{
    no collision
  }}
  sweep {{
    {sweep}
  }}
}}
"""


def _plan(sweep: str, assume: str = ""):
    result = compile_source(BASE.format(sweep=sweep, assume=assume), "s.addt")
    assert result.ok, result.diagnostics
    return result.plan


def test_grid_times_repeat_with_stable_ids_and_distinct_seeds():
    specs = expand(_plan("grid v in [5, 10, 15] m/s\n    repeat 2")).specs
    assert [s.run_id for s in specs] == [f"c{c:03d}-r{r:03d}" for c in range(3) for r in range(2)]
    assert [s.params["v"] for s in specs] == [5, 5, 10, 10, 15, 15]
    assert len({s.seed for s in specs}) == 6
    assert expand(_plan("grid v in [5, 10, 15] m/s\n    repeat 2")).specs == specs


@pytest.mark.parametrize("sampler", ["random", "halton", "lhs"])
def test_samplers_stay_in_range(sampler):
    specs = expand(_plan(f"{sampler} 20 seed 3")).specs
    assert len(specs) == 20
    assert all(5 <= s.params["v"] <= 20 and 10 <= s.params["gap"] <= 50 for s in specs)


def test_assumptions_reject_and_count():
    exp = expand(_plan("random 30 seed 1", assume="assume gap > 30 m"))
    assert len(exp.specs) == 30
    assert all(s.params["gap"] > 30 for s in exp.specs)
    assert exp.rejected["gap > 30 m"] > 0


def test_unsatisfiable_assumptions_are_an_error_not_a_loop():
    with pytest.raises(UnsatisfiableAssumptions):
        expand(_plan("random 10 seed 1", assume="assume gap > 60 m"))
