"""The samplers' defining properties, through `expand`: each test fails if Halton and
Latin hypercube sampling are replaced with plain uniform draws."""

import numpy as np
import pytest
from scipy.stats import qmc

from addt_dsl.compiler import compile_source
from addt_dsl.sweep import expand


def _units(dims: int, sampler: str) -> np.ndarray:
    """The sampled points, one row per run: every parameter spans [0, 1], so a parameter's
    value is the sampler's unit coordinate."""
    params = "\n".join(f"  param p{i} = 0.5 in [0, 1]" for i in range(dims))
    source = f"""
scenario s {{
  duration 5 s
  road r {{
    line length 300 m
  }}
{params}
  ego car on r lane -1 at 10 m speed 10 m/s
  expect {{
    no collision
  }}
  sweep {{
    {sampler}
  }}
}}
"""
    result = compile_source(source, "s.addt")
    assert result.ok, result.diagnostics
    specs = expand(result.plan).specs
    return np.array([[s.params[f"p{i}"] for i in range(dims)] for s in specs])


@pytest.mark.parametrize("dims,n", [(3, 17), (20, 64)])
def test_latin_hypercube_puts_one_sample_in_each_stratum_of_each_axis(dims, n):
    u = _units(dims, f"lhs {n} seed 5")
    assert u.shape == (n, dims)
    for axis in range(dims):
        assert sorted(np.floor(u[:, axis] * n).astype(int)) == list(range(n)), axis


@pytest.mark.parametrize("kind", ["halton", "lhs"])
def test_low_discrepancy_beats_plain_random_draws(kind):
    # Centred L2 discrepancy of 64 points in 4-D: uniform draws scatter around 0.017,
    # scrambled Halton stays near 0.002 and Latin hypercube near 0.004, for every seed.
    random = np.median([qmc.discrepancy(_units(4, f"random 64 seed {s}")) for s in range(5)])
    for seed in range(5):
        assert qmc.discrepancy(_units(4, f"{kind} 64 seed {seed}")) < 0.5 * random, seed


@pytest.mark.parametrize("seed", range(3))
def test_halton_axes_stay_distinct_and_even_past_sixteen_parameters(seed):
    # A Halton axis per prime base: with 20 parameters none may share a base (identical
    # axes), and each axis covers [0, 1] evenly: its 1-D discrepancy stays below 0.0015
    # where 64 uniform draws reach 0.007 to 0.013 on their worst of 20 axes.
    u = _units(20, f"halton 64 seed {seed}")
    corr = np.corrcoef(u.T)
    np.fill_diagonal(corr, 0.0)
    assert np.abs(corr).max() < 0.9
    for axis in range(20):
        assert qmc.discrepancy(u[:, [axis]]) < 0.003, axis


@pytest.mark.parametrize("kind", ["random", "halton", "lhs"])
def test_sampling_is_deterministic_in_the_plan_seed(kind):
    first = _units(3, f"{kind} 16 seed 9")
    assert np.array_equal(first, _units(3, f"{kind} 16 seed 9"))
    assert not np.array_equal(first, _units(3, f"{kind} 16 seed 10"))
