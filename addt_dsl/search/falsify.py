"""Falsification: search the parameter and fault space for oracle violations (`addtc falsify`).

The layout follows Hypothesis's conjecture engine: the space (`space.SearchSpace`: a unit
hypercube whose points are RunSpecs), the samplers that propose its points (`samplers`:
one `Sampler` protocol, a registry of uniform, cross-entropy, Bayesian optimisation,
bandit and CMA-ES), this driver, which asks a sampler for points, runs them, scores them
and groups the failures, and the report's rendering apart from its data (`render`).

Scores: each run is scored by its worst normalised robustness over the hard oracles not
yet falsified (the oracles' STL robustness, divided by its median size over the first
batch: below 0 the run fails). The default sampler, `bo`, models that score with a
Gaussian process and runs the candidate most likely to fail. Why not Hypothesis
`target()`: runs are expensive (0.1-1 s) and budgets small (tens to hundreds of runs), so
the search must spend each run where a model says; `target()` hill-climbs inside one
`@given` test, stops at the first failure, and budgets in examples that are cheap.

Distinct failures: a failing run is grouped by (oracle, mode, faults that injected); each
new group is shrunk (`shrink`) with a small budget, and its origin is what the shrunk run
still needs: the fault kinds and targets, and the parameters away from nominal with the
direction they moved (`origin_key`). Failures with the same oracle, mode and origin are
one failure; the report shows the values of the first one.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from addt_dsl.plan import RunSpec, ScenarioPlan
from addt_dsl.runtime.result import RunResult
from addt_dsl.search.cache import RunCache
from addt_dsl.search.samplers import DEFAULT_SAMPLER, SamplerContext, make_sampler
from addt_dsl.search.shrink import Shrinker, ShrinkResult
from addt_dsl.search.space import SearchSpace
from addt_dsl.sweep import derive_seed, violated_assumptions

MAX_SHRINKS = 8
CANDIDATE_TRIES = 50  # points proposed per point wanted before a search gives up on its `assume`s


@dataclass
class FoundFailure:
    oracle: str
    mode: str
    origin: str  # what the shrunk run still needs
    first_run: int  # 1-based index of the first search run that showed it
    count: int  # failing search runs in this group
    worst_robustness: float
    example: RunSpec
    shrunk: ShrinkResult | None = None


@dataclass
class FalsifyReport:
    scenario: str
    sampler: str
    runs: int
    seconds: float
    first_failure_run: int | None
    shrink_simulations: int
    failures: list[FoundFailure] = field(default_factory=list)
    best_robustness: dict[str, float] = field(default_factory=dict)
    ended_early: str = ""  # why the search stopped before its budget ("": it did not)

    def to_json(self) -> dict:
        return {
            "scenario": self.scenario, "sampler": self.sampler, "runs": self.runs, "ended_early": self.ended_early,
            "seconds": round(self.seconds, 3), "first_failure_run": self.first_failure_run,
            "shrink_simulations": self.shrink_simulations,
            "best_robustness": {k: (v if math.isfinite(v) else repr(v)) for k, v in self.best_robustness.items()},
            "failures": [{"oracle": f.oracle, "mode": f.mode, "origin": f.origin, "first_run": f.first_run,
                          "count": f.count, "worst_robustness": f.worst_robustness if math.isfinite(
                              f.worst_robustness) else repr(f.worst_robustness),
                          "example_key": f.example.key(),
                          "shrunk_key": f.shrunk.best.key() if f.shrunk else None} for f in self.failures],
        }


class Falsifier:
    def __init__(self, plan: ScenarioPlan, *, seed: int = 0, batch: int = 16, jobs: int = 1,
                 sampler: str = DEFAULT_SAMPLER, cache: RunCache | None = None, log=None, shrink_batch: int = 1):
        self.plan = plan
        self.shrink_batch = shrink_batch  # candidates each shrink runs together (`Shrinker`)
        self.space = SearchSpace(plan)
        self.seed = seed
        self.batch = max(2, batch)
        self.jobs = jobs
        self.cache = cache or RunCache()
        self.log = log or (lambda msg: None)
        rng = np.random.default_rng(derive_seed(seed, 31337))
        feasible = (lambda u: not violated_assumptions(plan, self.space.params_of(u))) if plan.assumptions else None
        self.sampler = make_sampler(sampler, SamplerContext(self.space.axes, rng, jobs, self.batch, feasible))
        self.hard = [o.name for o in plan.oracles if o.severity == "hard"]

    def _candidates(self, n: int, start: int) -> tuple[np.ndarray, list[RunSpec]]:
        """Up to `n` points that satisfy the assumptions, from at most `CANDIDATE_TRIES * n`
        the sampler proposes (fewer, or none, where the assumptions reject them all)."""
        points, specs = [], []
        tries = 0
        while len(specs) < n and tries < CANDIDATE_TRIES * n:
            for u in self.sampler.sample(n - len(specs)):
                tries += 1
                params = self.space.params_of(u)
                if violated_assumptions(self.plan, params):
                    continue  # an invalid sample is rejected, never run
                i = start + len(specs)
                specs.append(self.space.spec(u, derive_seed(self.seed, 7, i), f"f{i:05d}"))
                points.append(u)
        return np.array(points).reshape(len(points), self.space.dims), specs

    def _score(self, outcome: RunResult, targets: list[str], scales: dict[str, float]) -> float:
        if outcome.status != "ok" and "stack_health" in targets:
            return -math.inf
        vals = [outcome.robustness.get(n, math.inf) / scales.get(n, 1.0) for n in targets]
        vals = [v if not math.isnan(v) else -math.inf for v in vals]
        return min(vals) if vals else 0.0

    def run(self, budget_runs: int = 200, budget_seconds: float = 0.0, shrink_simulations: int = 60,
            stop_at_first: bool = False) -> FalsifyReport:
        try:
            return self._run(budget_runs, budget_seconds, shrink_simulations, stop_at_first)
        finally:
            self.cache.release_workers()  # the workers kept between batches

    def _run(self, budget_runs: int, budget_seconds: float, shrink_simulations: int,
             stop_at_first: bool) -> FalsifyReport:
        t0 = time.perf_counter()
        ended = ""
        all_points, all_outcomes, all_specs = [], [], []
        groups: dict[tuple, FoundFailure] = {}
        first_failure = None
        scales: dict[str, float] = {}
        falsified: set[str] = set()
        best = {n: math.inf for n in self.hard}
        while len(all_outcomes) < budget_runs:
            if budget_seconds and time.perf_counter() - t0 > budget_seconds:
                break
            n = min(self.sampler.batch_size(self.batch, len(all_outcomes)), budget_runs - len(all_outcomes))
            points, specs = self._candidates(n, len(all_outcomes))
            if not specs:
                ended = (f"the assumptions rejected all {CANDIDATE_TRIES * n} points the {self.sampler.name} "
                         f"sampler proposed after {len(all_outcomes)} runs")
                break
            outcomes = self.cache.get_many(specs, self.jobs)
            for k, (spec, outcome) in enumerate(zip(specs, outcomes)):
                run_no = len(all_outcomes) + k + 1
                for name in self.hard:
                    best[name] = min(best[name], outcome.robustness.get(name, math.inf))
                for fail in outcome.failures:
                    falsified.add(fail.oracle)
                    if first_failure is None:
                        first_failure = run_no
                    key = (fail.oracle, fail.mode, _injected_before(spec, outcome, fail.time_s))
                    g = groups.get(key)
                    if g is None:
                        groups[key] = FoundFailure(fail.oracle, fail.mode, "", run_no, 1, fail.robustness, spec)
                    else:
                        g.count += 1
                        if fail.robustness < g.worst_robustness:
                            g.worst_robustness, g.example = fail.robustness, spec
            all_points.append(points)
            all_outcomes += outcomes
            all_specs += specs
            if not scales:
                for name in self.hard:
                    vals = np.abs([o.robustness.get(name, 1.0) for o in all_outcomes])
                    vals = vals[np.isfinite(vals)]
                    scales[name] = float(np.median(vals)) if len(vals) and np.median(vals) > 0 else 1.0
            targets = [n for n in self.hard if n not in falsified] or list(self.hard)
            scores = np.array([self._score(o, targets, scales) for o in all_outcomes])
            self.sampler.update(np.concatenate(all_points), scores)
            self.log(f"{len(all_outcomes)} runs: {len(groups)} failing group(s); best "
                     + ", ".join(f"{k} {v:.3g}" for k, v in best.items()))
            if stop_at_first and first_failure is not None:
                break
        search_runs = len(all_outcomes)
        failures = self._distinct(groups, shrink_simulations)
        shrink_runs = sum(g.shrunk.simulations for g in groups.values() if g.shrunk is not None)
        return FalsifyReport(self.plan.name, self.sampler.name, search_runs, time.perf_counter() - t0,
                             first_failure, shrink_runs, failures, best, ended)

    def _distinct(self, groups: dict, shrink_simulations: int) -> list[FoundFailure]:
        """Shrink one representative per group; merge groups whose origin is the same."""
        out: dict[tuple, FoundFailure] = {}
        for i, g in enumerate(sorted(groups.values(), key=lambda g: g.first_run)):
            if shrink_simulations > 0 and i < MAX_SHRINKS:
                try:
                    g.shrunk = Shrinker(g.example, nominal_plan=self.plan, oracle=g.oracle, cache=self.cache,
                                        max_simulations=shrink_simulations, batch=self.shrink_batch,
                                        jobs=self.jobs).run()
                except ValueError:
                    g.shrunk = None
            best = g.shrunk.best if g.shrunk else g.example
            g.origin = origin_of(best, self.space.nominal)
            key = (g.oracle, g.mode, origin_key(best, self.space.nominal))
            if key in out:
                other = out[key]
                other.count += g.count
                other.first_run = min(other.first_run, g.first_run)
            else:
                out[key] = g
        return sorted(out.values(), key=lambda g: g.first_run)


def _injected_before(spec: RunSpec, outcome: RunResult, t: float | None) -> tuple:
    """Fault kinds/targets that injected anything in the run (cheap grouping before shrinking)."""
    return tuple(sorted({(f.kind, f.target) for f in spec.faults if outcome.injections.get(f.index)}))


def origin_key(spec: RunSpec, nominal: dict[str, float]) -> tuple:
    """The region a failure comes from, coarsely: which faults (kind, target) it needs and
    which parameters it needs away from nominal, in which direction."""
    faults = tuple(sorted({(f.kind, f.target) for f in spec.faults}))
    params = tuple(sorted((k, "+" if v > nominal[k] else "-") for k, v in spec.params.items()
                          if k in nominal and v != nominal[k]))
    return faults, params


def origin_of(spec: RunSpec, nominal: dict[str, float]) -> str:
    """What a (shrunk) failing run contains beyond the nominal scenario."""
    parts = []
    for f in spec.faults:
        settings = " ".join(f"{k} {_short(v)}" for k, v in sorted(f.settings.items()))
        window = (("when its condition holds" + (f", for {_short(f.end_s)} s" if f.end_s is not None else ""))
                  if f.opens is not None else
                  f"from {_short(f.start_s)} s" if f.end_s is None else
                  f"at {_short(f.start_s)} s" if f.end_s == f.start_s else
                  f"during [{_short(f.start_s)} s, {_short(f.end_s)} s]")
        parts.append(f"{f.kind} {f.target} {settings} {window}".replace("  ", " "))
    for k, v in sorted(spec.params.items()):
        if k in nominal and v != nominal[k]:
            parts.append(f"{k} = {_short(v)} (nominal {_short(nominal[k])})")
    return "; ".join(parts) if parts else "nominal scenario (no fault, nominal parameters)"


def _short(v) -> str:
    return f"{v:.4g}" if isinstance(v, float) else str(v)
