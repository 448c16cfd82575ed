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


def _plan(sweep: str, assume: str = "", template: str = BASE):
    result = compile_source(template.format(sweep=sweep, assume=assume), "s.addt")
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
    # Caught at compile time (E0501: the compiler probes the sweep's candidates) ...
    result = compile_source(BASE.format(sweep="random 10 seed 1", assume="assume gap > 60 m"), "s.addt")
    assert [d.code for d in result.diagnostics if d.is_error] == ["E0501"]
    # ... and at expansion when sampling rejects more than the cap allows.
    with pytest.raises(UnsatisfiableAssumptions):
        expand(_plan("random 10 seed 1\n    max_rejections 3", assume="assume gap > 49 m"))


PAIRED = """
scenario p {{
  duration 5 s
  road r {{
    line length 300 m
  }}
  param v = 10 m/s in [5 m/s, 20 m/s]
  param rate = 1 % in [0 %, 50 %]
  param window = 1 s in [0 s, 4 s]
  param unused = 1 in [0, 9]
  ego car on r lane -1 at 10 m speed v {{
    sensor lidar
  }}
  faults {{
    during [window, 5 s] drop lidar rate rate
  }}
  {assume}
  sweep {{
    {sweep}
  }}
}}
"""


def _paired(sweep: str, extra: str = ""):
    return _plan(sweep, assume=extra, template=PAIRED)


def test_fault_only_parameters_are_those_only_the_faults_read():
    assert _paired("repeat 1").fault_only_params() == {"rate", "window"}
    # Read by an oracle too: not fault-only. A parameter nothing reads is not either.
    plan = _paired("repeat 1", extra="expect {\n    always ego.speed < 40 m/s + window / 1 s * 1 m/s\n  }")
    assert plan.fault_only_params() == {"rate"}


def test_cells_differing_only_in_fault_parameters_share_seeds_and_golden_twins():
    from addt_dsl.runtime.outcome import golden_spec

    specs = expand(_paired("grid rate in [1, 5, 10] %\n    grid v in [10, 15] m/s\n    repeat 3")).specs
    assert len(specs) == 18
    seeds = {}
    for s in specs:
        seeds.setdefault(s.params["rate"], []).append((s.params["v"], s.repeat_index, s.seed))
    assert seeds[0.01] == seeds[0.05] == seeds[0.1]  # paired across rates
    assert len({s.seed for s in specs}) == 6  # apart across speeds and repeats
    assert len({golden_spec(s).key() for s in specs}) == 6
    assert all("rate" not in golden_spec(s).params for s in specs)
    # Unchanged where no axis is fault-only: the seed derives from the cell index, as before.
    specs_v = expand(_paired("grid v in [10, 15] m/s\n    grid unused in [1, 2]\n    repeat 3")).specs
    assert len({s.seed for s in specs_v}) == 12


def test_samples_are_paired_across_fault_only_cells():
    specs = expand(_paired("grid rate in [1, 10] %\n    random 4 seed 2")).specs
    by_rate = {r: [(s.params["v"], s.seed) for s in specs if s.params["rate"] == r] for r in (0.01, 0.1)}
    assert by_rate[0.01] == by_rate[0.1]
    assert len({v for v, _ in by_rate[0.01]}) == 4
