"""The samplers' registry: the split of the search into space, samplers and driver kept
every sampler's candidates; CMA-ES through `cma` is deterministic and searches."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from tests.unit.search.candidate_trace import (MACHINE_DEPENDENT, ROOT, SAMPLERS, SCENARIOS, candidate_digest,
                                              machine, synthetic_scores)

from addt_dsl.compiler import compile_file
from addt_dsl.search.falsify import Falsifier
from addt_dsl.search.samplers import SAMPLERS as REGISTRY
from addt_dsl.search.samplers import SamplerContext, make_sampler
from addt_dsl.search.samplers.cmaes import CmaEsSampler
from addt_dsl.search.space import Axis

BEFORE = json.loads((ROOT / "tests" / "data" / "search" / "candidate_digests.json").read_text())


@pytest.mark.slow
@pytest.mark.parametrize("path", SCENARIOS, ids=lambda p: p.stem)
def test_same_seeds_same_candidates_as_recorded(path: Path):
    """Every sampler's candidates as recorded; the Gaussian-process samplers' only on a
    machine like the one that recorded them (candidate_trace.py says why)."""
    plan = compile_file(path).plan
    samplers = SAMPLERS if machine() == BEFORE["_machine"] else [s for s in SAMPLERS if s not in MACHINE_DEPENDENT]
    got = {f"{path.relative_to(ROOT)}:{s}:{seed}": candidate_digest(plan, s, seed) for s in samplers for seed in (0, 1)}
    assert got == {k: BEFORE[k] for k in got}


def test_cli_choices_come_from_the_registry():
    from addt_dsl.cli import build_parser

    fal = build_parser()._subparsers._group_actions[0].choices["falsify"]
    action = next(a for a in fal._actions if a.dest == "sampler")
    assert tuple(action.choices) == tuple(REGISTRY) and {"bo", "bandit", "cem", "random", "cmaes"} <= set(REGISTRY)
    for spec in REGISTRY.values():
        assert spec.load().name == spec.name


def test_unknown_sampler_is_refused():
    plan = compile_file(SCENARIOS[0]).plan
    with pytest.raises(ValueError, match="unknown sampler 'nelder'"):
        Falsifier(plan, sampler="nelder")


AXES = [Axis(f"param:x{i}", "unit") for i in range(4)] + [Axis("fault0:present", "bool", severe=1.0)]


def cmaes(seed: int, batch: int = 8):
    return make_sampler("cmaes", SamplerContext(AXES, np.random.default_rng(seed), jobs=2, batch=batch))


def drive(sampler, runs: int, score=synthetic_scores) -> tuple[np.ndarray, int | None]:
    """Points a sampler proposes over `runs` runs of `score`; the run of the first score below 0."""
    points = np.empty((0, len(AXES)))
    first = None
    while len(points) < runs:
        new = sampler.sample(min(sampler.batch_size(8, len(points)), runs - len(points)))
        points = np.vstack([points, new])
        scores = score(points)
        if first is None and (scores < 0).any():
            first = int(np.argmax(scores < 0)) + 1
        sampler.update(points, scores)
    return points, first


def test_cmaes_same_seed_same_points_and_no_global_numpy_state():
    np.random.seed(5)
    state = np.random.get_state()[1].copy()
    a, _ = drive(cmaes(3), 64)
    assert np.array_equal(np.random.get_state()[1], state)  # `cma` neither reads nor reseeds it
    np.random.seed(99)  # a different global state changes nothing
    b, _ = drive(cmaes(3), 64)
    c, _ = drive(cmaes(4), 64)
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    assert a.shape == (64, len(AXES)) and (a >= 0).all() and (a <= 1).all()
    assert isinstance(cmaes(0), CmaEsSampler) and cmaes(0).popsize == 8


def narrow(points: np.ndarray) -> np.ndarray:
    """Below 0 only within 0.08 (per sqrt(axes)) of (0.8, 0.2, 0.7, 0.3) with the fault present:
    about 0.1 % of the cube."""
    d = np.linalg.norm(points[:, :4] - [0.8, 0.2, 0.7, 0.3], axis=1) / 2.0
    return d - 0.08 + np.where(points[:, 4] >= 0.5, 0.0, 0.05)


def test_cmaes_finds_a_small_region_far_sooner_than_uniform():
    cma_runs = sorted(drive(cmaes(s), 400, narrow)[1] or 401 for s in range(5))
    uniform = [make_sampler("random", SamplerContext(AXES, np.random.default_rng(s))) for s in range(5)]
    uni_runs = sorted(drive(u, 400, narrow)[1] or 401 for u in uniform)
    assert cma_runs[2] < 150 and cma_runs[2] * 2 < uni_runs[2], (cma_runs, uni_runs)


def test_cmaes_infinite_scores_and_restarts():
    """A crash (-inf) and a never-violable oracle (+inf) do not break `cma`; a distribution
    that converged (here on a flat score) starts again elsewhere, so a long search keeps
    proposing new points."""
    s = cmaes(1, batch=4)
    first = s.es
    pts, _ = drive(s, 400, lambda p: np.where(p[:, 0] > 0.9, -np.inf, np.where(p[:, 1] > 0.9, np.inf, 0.0)))
    assert s.es is not first  # restarted
    assert np.isfinite(pts).all() and (pts >= 0).all() and (pts <= 1).all()
    assert len(np.unique(np.round(pts[-100:], 6), axis=0)) == 100
