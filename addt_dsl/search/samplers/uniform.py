"""Uniform sampling over the search space (`--sampler random`): the benchmark's baseline."""

from __future__ import annotations

import numpy as np

from addt_dsl.search.samplers import SamplerContext


class UniformSampler:
    name = "random"

    def __init__(self, dims: int, rng: np.random.Generator):
        self.dims, self.rng = dims, rng

    @classmethod
    def create(cls, ctx: SamplerContext) -> UniformSampler:
        return cls(len(ctx.axes), ctx.rng)

    def batch_size(self, default: int, done: int) -> int:
        return default

    def sample(self, n: int) -> np.ndarray:
        return self.rng.random((n, self.dims))

    def update(self, points: np.ndarray, scores: np.ndarray) -> None:
        pass

