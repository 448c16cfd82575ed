"""The candidate sequence a sampler proposes on a scenario, for a seed, under a fixed
synthetic score (no simulation): the points and the RunSpecs' parameters, faults and
seeds, one digest per search. `tests/data/search/candidate_digests.json` holds the
digests the four samplers gave (test_sampler_registry.py compares).

`random` and `cem` give the same candidates on any machine. `bo` and `bandit` fit Gaussian
processes (scikit-learn, LAPACK through OpenBLAS, numpy's SIMD transcendentals), whose last
bits depend on the machine: their digests hold on a machine like the one that made them,
which the file names under `_machine` (OpenBLAS's kernel, whether numpy has AVX-512).

Regenerate (only when a sampler's behaviour is meant to change), on a machine whose OpenBLAS
takes its SkylakeX kernels (CI's; elsewhere `OPENBLAS_CORETYPE=SkylakeX` stands in):
    PYTHONPATH=. python tests/unit/search/candidate_trace.py > tests/data/search/candidate_digests.json
"""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[3]
SCENARIOS = sorted((ROOT / "examples" / "search").glob("**/*.addt"))
SAMPLERS = ("random", "cem", "bo", "bandit")
MACHINE_DEPENDENT = ("bo", "bandit")


def machine() -> dict:
    """What the machine-dependent samplers' digests depend on: OpenBLAS's kernel, numpy's AVX-512."""
    from numpy._core import _multiarray_umath as m
    from threadpoolctl import threadpool_info

    blas = sorted(i.get("architecture", "") for i in threadpool_info() if i.get("internal_api") == "openblas")
    return {"openblas": blas, "numpy_avx512": bool(m.__cpu_features__.get("AVX512F"))
            and "X86_V4" in [f for f in m.__cpu_dispatch__ if m.__cpu_features__.get(f)]}
BATCH, JOBS, RUNS = 8, 2, 40  # the search benchmark's batch and jobs


def synthetic_scores(points: np.ndarray) -> np.ndarray:
    """Distance from the point 0.3 on every axis, per sqrt(axes), less 0.1: a small region scores below 0."""
    return np.linalg.norm(points - 0.3, axis=1) / np.sqrt(points.shape[1]) - 0.1


def candidate_digest(plan, sampler: str, seed: int, runs: int = RUNS) -> str:
    from addt_dsl.search.falsify import Falsifier

    fal = Falsifier(plan, seed=seed, batch=BATCH, jobs=JOBS, sampler=sampler)
    h = hashlib.sha256()
    all_points = []
    done = 0
    while done < runs:
        n = min(fal.sampler.batch_size(fal.batch, done), runs - done)
        points, specs = fal._candidates(n, done)
        if not specs:
            break
        for u, spec in zip(points, specs):
            h.update(np.round(u, 12).tobytes())
            faults = [(f.index, f.kind, f.target, round(f.start_s, 9), None if f.end_s is None else round(f.end_s, 9),
                       sorted((k, round(v, 9) if isinstance(v, float) else v) for k, v in f.settings.items()), f.seed)
                      for f in spec.faults]
            h.update(repr((sorted(spec.params.items()), spec.seed, spec.run_id, faults)).encode())
        all_points.append(points)
        done += len(specs)
        pts = np.concatenate(all_points)
        fal.sampler.update(pts, synthetic_scores(pts))
    return h.hexdigest()[:20]


def main() -> None:
    from addt_dsl.compiler import compile_file

    out = {"_machine": machine()}
    for path in SCENARIOS:
        plan = compile_file(path).plan
        for sampler in SAMPLERS:
            for seed in (0, 1):
                out[f"{path.relative_to(ROOT)}:{sampler}:{seed}"] = candidate_digest(plan, sampler, seed)
                print(f"{path.name} {sampler} {seed}", file=sys.stderr, flush=True)
    json.dump(out, sys.stdout, indent=1, sort_keys=True)
    print()


if __name__ == "__main__":
    main()
