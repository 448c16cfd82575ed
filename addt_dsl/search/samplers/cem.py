"""The cross-entropy method (`--sampler cem`): per-axis distributions refitted to the best
fifth of the points so far."""

from __future__ import annotations

import math

import numpy as np

from addt_dsl.kernel import log, matmul
from addt_dsl.search.samplers import SamplerContext
from addt_dsl.search.space import Axis

ELITE_FRACTION = 0.2
EXPLORE_FRACTION = 0.1
SMOOTHING = 0.7
MIN_SIGMA = 0.03
MIN_ELITE = 5
MIN_POINTS = 16  # uniform samples before the first fit (at least twice the dimensions)


class CrossEntropySampler:
    """Independent per-axis truncated normals (Bernoulli for bool axes), refit to elites."""

    name = "cem"

    def __init__(self, axes: list[Axis], rng: np.random.Generator):
        self.rng = rng
        self.bool = np.array([a.kind == "bool" for a in axes], dtype=bool)
        self.mu = np.full(len(axes), 0.5)
        self.sigma = np.full(len(axes), 0.5)
        self.p = np.full(len(axes), 0.5)  # the first batch is uniform, like random sampling
        self.fitted = False

    @classmethod
    def create(cls, ctx: SamplerContext) -> CrossEntropySampler:
        return cls(ctx.axes, ctx.rng)

    def batch_size(self, default: int, done: int) -> int:
        return default

    def sample(self, n: int) -> np.ndarray:
        d = len(self.mu)
        if not self.fitted:
            u = self.rng.random((n, d))
            u[:, self.bool] = (self.rng.random((n, int(self.bool.sum()))) < self.p[self.bool]).astype(float)
            return u
        n_explore = int(round(EXPLORE_FRACTION * n))
        u = self.rng.random((n, d))
        guided = self._truncated(n - n_explore)
        u[n_explore:] = guided
        return u

    def _truncated(self, n: int) -> np.ndarray:
        d = len(self.mu)
        out = np.empty((n, d))
        for j in range(d):
            if self.bool[j]:
                out[:, j] = (self.rng.random(n) < self.p[j]).astype(float)
                continue
            col = self.rng.normal(self.mu[j], self.sigma[j], n)
            bad = (col < 0) | (col > 1)
            for _ in range(20):  # resample outside [0, 1]; clip what is left
                if not bad.any():
                    break
                col[bad] = self.rng.normal(self.mu[j], self.sigma[j], int(bad.sum()))
                bad = (col < 0) | (col > 1)
            out[:, j] = np.clip(col, 0.0, 1.0)
        return out

    def update(self, points: np.ndarray, scores: np.ndarray) -> None:
        """Refit to the best `ELITE_FRACTION` of all points so far (lower score is better),
        rank-weighted (log weights, as in CMA-ES), once there are enough points."""
        if len(points) < max(MIN_POINTS, 2 * len(self.mu)):
            return
        n = max(MIN_ELITE, int(math.ceil(ELITE_FRACTION * len(points))))
        elite = points[np.argsort(scores, kind="stable")[:n]]
        w = log.over(n + 0.5) - log.over(np.arange(1, n + 1))
        w /= w.sum()
        mu = matmul(w, elite)  # (not numpy's `@`: BLAS sums by the machine's kernel)
        sigma = np.sqrt(matmul(w, (elite - mu) ** 2))
        self.mu = SMOOTHING * mu + (1 - SMOOTHING) * self.mu
        self.sigma = np.maximum(SMOOTHING * sigma + (1 - SMOOTHING) * self.sigma, MIN_SIGMA)
        self.p = np.clip(SMOOTHING * mu + (1 - SMOOTHING) * self.p, 0.05, 0.95)
        self.fitted = True

