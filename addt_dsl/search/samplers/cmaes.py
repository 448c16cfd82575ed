"""CMA-ES over the search space (`--sampler cmaes`), through the maintained `cma` package.

One generation is one batch of `ctx.batch` points (the population size), drawn from a
normal distribution whose mean, step size and covariance `cma` adapts to the ranks of
the scores; the cube's bounds through `cma`'s boundary transformation, so every point it
asks is inside [0, 1]. A boolean axis (a fault present or absent) is the point's side of
0.5, as for the other samplers.

The points the driver runs come back through `update`; a generation is told to `cma` once
`popsize` of its points have a score (points an `assume` rejected are never run, so a
generation can take more than one batch to fill), with the scores as they stand then (they
change when an oracle is falsified). Scores of -inf (a crash) and +inf (an oracle that
cannot be violated) are clipped one beyond the finite range, as for `bo`; CMA-ES uses
ranks only. When `cma` reports the distribution converged (`stop()`), a fresh one starts
at a random point of the cube (a restart), so a long search keeps looking for the other
oracles' failures.

Determinism: `cma`'s normal deviates come from the search's generator (`randn`), and its
`seed` option is off (NaN), so `cma` neither reads nor reseeds NumPy's global generator.
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from addt_dsl.search.samplers import SamplerContext

SIGMA0 = 0.3  # initial step size, in units of the cube's side
# `stop()` reasons that are not convergence (the budget of the driver is the limit).
NOT_CONVERGED = {"maxfevals", "maxiter", "ftarget"}


class CmaEsSampler:
    name = "cmaes"

    def __init__(self, dims: int, rng: np.random.Generator, popsize: int):
        self.dims, self.rng = dims, rng
        self.popsize = max(2, popsize)
        self.queue: list[np.ndarray] = []  # asked, not yet handed out
        self.told = 0  # points of the driver's list already accounted for
        self.waiting: list[int] = []  # indices (driver's list) of run points of the current generation
        self.es = self._start(np.full(dims, 0.5)) if dims else None

    @classmethod
    def create(cls, ctx: SamplerContext) -> CmaEsSampler:
        return cls(len(ctx.axes), ctx.rng, ctx.batch)

    def _start(self, x0: np.ndarray):
        import cma

        def randn(*shape: int) -> np.ndarray:
            return self.rng.standard_normal(shape)

        opts = {"bounds": [0.0, 1.0], "popsize": self.popsize, "seed": math.nan, "randn": randn,
                "verbose": -9, "verb_disp": 0, "verb_log": 0, "verb_filenameprefix": "", "CMA_diagonal": False}
        if self.dims == 1:  # `cma` warns that 1-D is not its domain; it works
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                return cma.CMAEvolutionStrategy(x0, SIGMA0, opts)
        return cma.CMAEvolutionStrategy(x0, SIGMA0, opts)

    def batch_size(self, default: int, done: int) -> int:
        return self.popsize

    def sample(self, n: int) -> np.ndarray:
        if self.es is None:
            return self.rng.random((n, self.dims))
        out = []
        while len(out) < n:
            if not self.queue:
                self.queue = [np.asarray(x, dtype=float) for x in self.es.ask()]
            out.append(self.queue.pop(0))
        return np.array(out)

    def update(self, points: np.ndarray, scores: np.ndarray) -> None:
        if self.es is None:
            return
        self.waiting += range(self.told, len(points))
        self.told = len(points)
        finite = scores[np.isfinite(scores)]
        lo, hi = (finite.min() - 1.0, finite.max() + 1.0) if len(finite) else (-1.0, 1.0)
        y = np.clip(np.nan_to_num(scores, nan=hi, posinf=hi, neginf=lo), lo, hi)
        while len(self.waiting) >= self.popsize:
            gen, self.waiting = self.waiting[:self.popsize], self.waiting[self.popsize:]
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # points asked by an earlier generation: `cma` adopts them
                self.es.tell([points[i] for i in gen], [float(y[i]) for i in gen])
            if set(self.es.stop()) - NOT_CONVERGED:
                self.es = self._start(self.rng.random(self.dims))
                self.queue, self.waiting = [], []
