"""The Bayesian-optimisation sampler on synthetic scores (no simulation): it reaches a small
failure region in far fewer evaluations than uniform sampling, a batch's points are spread,
and crashes (-inf) or unviolable oracles (+inf) do not break the model."""

from __future__ import annotations

import numpy as np

from addt_dsl.search.falsify import BO_SPREAD, Axis, BayesianSampler, UniformSampler

DIMS = 3


def score(u: np.ndarray) -> np.ndarray:
    """Robustness-like: negative only within 0.28 of the corner (1, 1, 0), 1.15 % of the cube."""
    return np.sqrt((1 - u[..., 0]) ** 2 + (1 - u[..., 1]) ** 2 + u[..., 2] ** 2) - 0.28


def runs_to_failure(sampler, budget: int) -> int:
    points, scores = np.empty((0, DIMS)), np.empty(0)
    while len(scores) < budget:
        batch = sampler.sample(sampler.batch_size(8, len(scores)))
        for u in batch:
            points, scores = np.vstack([points, u]), np.append(scores, score(u))
            if scores[-1] < 0:
                return len(scores)
        sampler.update(points, scores)
    return budget + 1


def test_bo_reaches_a_small_failure_region_in_a_few_runs():
    axes = [Axis(f"param:p{i}", "unit") for i in range(DIMS)]
    bo = [runs_to_failure(BayesianSampler(axes, np.random.default_rng(s)), 40) for s in range(3)]
    uniform = [runs_to_failure(UniformSampler(DIMS, np.random.default_rng(s)), 400) for s in range(3)]
    assert np.median(bo) <= 15, bo
    assert np.median(uniform) > 2 * np.median(bo), (uniform, bo)


def test_a_batch_is_spread_and_infinite_scores_are_tolerated():
    axes = [Axis(f"param:p{i}", "unit") for i in range(DIMS)]
    sampler = BayesianSampler(axes, np.random.default_rng(0), jobs=4)
    first = sampler.sample(sampler.batch_size(8, 0))
    assert first.shape == (sampler.initial, DIMS)
    scores = score(first)
    scores[0], scores[1] = -np.inf, np.inf  # a crashed run, an oracle that cannot be violated
    sampler.update(first, scores)
    batch = sampler.sample(sampler.batch_size(8, len(first)))
    assert batch.shape == (4, DIMS) and np.all((batch >= 0) & (batch <= 1))
    gaps = [np.linalg.norm(a - b) for i, a in enumerate(batch) for b in batch[i + 1:]]
    assert min(gaps) >= BO_SPREAD * np.sqrt(DIMS) - 1e-12


def test_same_seed_same_points():
    axes = [Axis(f"param:p{i}", "unit") for i in range(DIMS)]
    runs = []
    for _ in range(2):
        s = BayesianSampler(axes, np.random.default_rng(3))
        u = s.sample(s.batch_size(8, 0))
        s.update(u, score(u))
        runs.append(s.sample(2))
    assert np.array_equal(runs[0], runs[1])
