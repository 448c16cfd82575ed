"""Samplers of the search space: one protocol, one registry (`SAMPLERS`).

A sampler proposes points of the unit cube (`sample`), is told every point run so far
with its score (`update`: the worst normalised robustness over the hard oracles not yet
falsified; below 0 the run failed; lower is better), and says how many points the driver
asks for next (`batch_size`). Every sampler is deterministic for its `rng` and keeps
going after a failure, to look for the other oracles' failures.

The registry holds each sampler's name, one-line summary and where its implementation
lives; the implementation (scikit-learn's Gaussian process, the `cma` package) is imported
only when a search builds that sampler, so the CLI lists the choices without loading them.
`--sampler` takes these names, and docs/falsify-and-shrink.md's table of samplers is
generated from this registry (docs/regen.py).
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable, Protocol

if TYPE_CHECKING:  # annotations only: the registry loads without NumPy
    import numpy as np

    from addt_dsl.search.space import Axis


@dataclass(frozen=True)
class SamplerContext:
    """What the driver gives a sampler to build it."""

    axes: list[Axis]
    rng: np.random.Generator
    jobs: int = 1  # runs at a time (a model-based sampler proposes that many per step)
    batch: int = 16  # the driver's batch (`--batch`): points per generation of population samplers
    feasible: Callable[[np.ndarray], bool] | None = None  # a point satisfies the `assume`s (None: all do)


class Sampler(Protocol):
    name: str

    def batch_size(self, default: int, done: int) -> int:
        """Points wanted next, after `done` runs (`default`: the driver's batch)."""

    def sample(self, n: int) -> np.ndarray:
        """`n` points of the unit cube, shape (n, axes)."""

    def update(self, points: np.ndarray, scores: np.ndarray) -> None:
        """Every point run so far and its score (scores change when an oracle is falsified)."""


@dataclass(frozen=True)
class SamplerSpec:
    name: str  # the `--sampler` keyword
    summary: str  # one line for `--help` and the docs' table
    implementation: str  # "module:Class"; the class has `create(ctx: SamplerContext)`

    def load(self) -> type:
        module, cls = self.implementation.split(":")
        return getattr(importlib.import_module(module), cls)


SAMPLERS: dict[str, SamplerSpec] = {s.name: s for s in (
    SamplerSpec("bo", "Bayesian optimisation of the failure probability (Gaussian process, trust region)",
                "addt_dsl.search.samplers.bo:BayesianSampler"),
    SamplerSpec("bandit", "Thompson sampling over which fault is present, Bayesian optimisation inside "
                          "(for many faults)", "addt_dsl.search.samplers.bandit:BanditSampler"),
    SamplerSpec("cmaes", "CMA-ES (the `cma` package): a covariance-adapting normal distribution, one "
                         "generation per batch", "addt_dsl.search.samplers.cmaes:CmaEsSampler"),
    SamplerSpec("cem", "cross-entropy method: per-axis distributions refitted to the best fifth",
                "addt_dsl.search.samplers.cem:CrossEntropySampler"),
    SamplerSpec("random", "uniform sampling (the benchmark's baseline)",
                "addt_dsl.search.samplers.uniform:UniformSampler"),
)}
DEFAULT_SAMPLER = "bo"


def make_sampler(name: str, ctx: SamplerContext) -> Sampler:
    spec = SAMPLERS.get(name)
    if spec is None:
        raise ValueError(f"unknown sampler {name!r}: one of {', '.join(SAMPLERS)}")
    return spec.load().create(ctx)


def markdown_table() -> str:
    """The registry as the Markdown table of docs/falsify-and-shrink.md."""
    lines = ["| `--sampler` | what it does | implementation |", "| --- | --- | --- |"]
    for s in SAMPLERS.values():
        module, cls = s.implementation.split(":")
        default = " (default)" if s.name == DEFAULT_SAMPLER else ""
        lines.append(f"| `{s.name}`{default} | {s.summary} | `{cls}` in `{module.replace('.', '/')}.py` |")
    return "\n".join(lines) + "\n"
