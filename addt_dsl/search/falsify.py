"""Falsification: search the parameter and fault space for oracle violations.

The space (`SearchSpace`) is a unit hypercube. Its axes: every parameter with a range
or choices (grid values count as choices); per declared fault, whether it is present,
its start time and window length, and each constant numeric setting (from its neutral
value to twice the declared one, inside the registry's range; counts from 1), plus the
bit for bit flips with a fixed bit. Settings written with a parameter move with that
parameter. Fault seeds and the run seed are drawn afresh for every candidate.

Guidance (`SAMPLERS`): each run is scored by its worst normalised robustness over the hard
oracles not yet falsified (the oracles' STL robustness: below 0 the run fails), and the
default sampler, `BayesianSampler`, models that score with a Gaussian process and runs the
candidate most likely to fail, from a Latin hypercube start (faults in it at their severe
ends) and a trust region around the lowest score (see its docstring). `BanditSampler`
(for schedules of many faults) picks which fault is present by Thompson sampling and runs a
`BayesianSampler` in that fault's slice of the space. `CrossEntropySampler` (CEM: per-axis distributions
refitted to the best fifth of each batch) and `UniformSampler` (the benchmark's baseline)
are the options. Why not Hypothesis `target()`: runs are expensive (0.1-1 s) and budgets
small (tens to hundreds of runs), so the search must spend each run where a model says;
`target()` hill-climbs inside one `@given` test, stops at the first failure, and budgets in
examples that are cheap. Every sampler is deterministic for a seed and keeps going after a
failure to look for the other oracles' failures.

Distinct failures: a failing run is grouped by (oracle, mode, faults that injected); each
new group is shrunk (`shrink`) with a small budget, and its origin is what the shrunk run
still needs: the fault kinds and targets, and the parameters away from nominal with the
direction they moved (`origin_key`). Failures with the same oracle, mode and origin are
one failure; the report shows the values of the first one.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import norm, qmc
from sklearn.exceptions import ConvergenceWarning
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import ConstantKernel, Matern, WhiteKernel
from threadpoolctl import threadpool_limits

from addt_dsl import expr as E
from addt_dsl.plan import RunSpec, ScenarioPlan
from addt_dsl.registry import FAULTS
from addt_dsl.runtime.result import RunResult
from addt_dsl.search import candidates as C
from addt_dsl.search.cache import RunCache
from addt_dsl.search.shrink import Shrinker, ShrinkResult
from addt_dsl.sweep import from_unit, concrete_faults, derive_seed, violated_assumptions

ELITE_FRACTION = 0.2
EXPLORE_FRACTION = 0.1
SMOOTHING = 0.7
MIN_SIGMA = 0.03
MIN_ELITE = 5
MIN_POINTS = 16  # uniform samples before the first fit (at least twice the dimensions)
MAX_SHRINKS = 8
CANDIDATE_TRIES = 50  # points proposed per point wanted before a search gives up on its `assume`s
# Bayesian optimisation (BayesianSampler)
BO_MIN_INITIAL = 4  # uniform points before the first model (at least half the axes)
BO_CANDIDATES = 2000  # uniform candidates per choice, and as many around the best points
# Trust region (TuRBO): mean side of the box around the best point, as a fraction of the cube
TR_LENGTH_INIT, TR_LENGTH_MIN, TR_LENGTH_MAX = 0.4, 0.05, 0.8
TR_SUCCESSES, TR_FAILURES = 2, 3  # improving batches to double it; batches without to halve it
BO_SPREAD = 0.05  # minimum distance between the points of one batch, per sqrt(axes)
BO_MAX_POINTS = 200  # points the model is fitted to (the lowest scores)
WARP_SCALE = 0.05  # scores (robustness / its median size) are modelled as sign * log(1 + |score| / WARP_SCALE)
BANDIT_MIN_MODEL = 4  # pulls of a bandit arm with its fault at the worst case; runs before an arm's model
SAMPLERS = ("bo", "bandit", "cem", "random")


# ---------------------------------------------------------------- the space

@dataclass(frozen=True)
class Axis:
    name: str  # `param:gap`, `fault3:present`, `fault3:start`, `fault3:length`, `fault3:value`, ...
    kind: str  # "unit" (continuous) | "bool"
    decode: object = None  # callable(u) -> value (for reporting)
    # A fault axis's most severe end (present, from the start, for the whole run, the
    # setting farthest from neutral); None: no severe end (parameters, drawn bits, instants).
    severe: float | None = None


class SearchSpace:
    def __init__(self, plan: ScenarioPlan):
        self.plan = plan
        self.nominal = plan.nominal_params()
        self.axes: list[Axis] = []
        grid = {g.param: g.values for g in plan.sweep.grid}
        self.params = []
        for p in plan.params:
            choices = list(p.choices) or (grid.get(p.name) if (p.low is None or p.high is None) else None)
            if choices and len(set(choices)) > 1:
                self.params.append((p, choices))
            elif p.low is not None and p.high is not None and p.low < p.high:
                self.params.append((p, None))
            else:
                continue
            self.axes.append(Axis(f"param:{p.name}", "unit"))
        nominal_faults = concrete_faults(plan, self.nominal, plan.seed)
        self.faults = []  # (index, concrete at nominal, [(setting, lo, hi, integer)], instant, fixed_length)
        for f, fp in zip(nominal_faults, plan.faults):
            cls = FAULTS.get(f.kind)
            specs = {s.name: s for s in cls.params}
            settings = []
            severe: dict[str, float] = {}  # setting -> its unit value farthest from neutral
            for name, value in f.settings.items():
                spec = specs.get(name)
                expr = fp.settings.get(name)
                if spec is None or not isinstance(value, float) or isinstance(expr, (str, list)):
                    continue
                if expr is not None and E.params_used(expr):
                    continue  # moves with its parameter
                if name == C.drawn_setting(f.kind):
                    if value >= 0:
                        settings.append((name, 0.0, 63.0, True))
                    continue
                neutral = C.neutral_value(f.kind, name)
                lo, hi = sorted((neutral, neutral + 2.0 * (value - neutral)))
                lo = max(lo, spec.low) if spec.low is not None else lo
                hi = min(hi, spec.high) if spec.high is not None else hi
                if spec.kind == "int":
                    lo = max(lo, 1.0)
                if hi > lo:
                    settings.append((name, lo, hi, spec.kind == "int"))
                    severe[name] = 1.0 if abs(hi - neutral) >= abs(lo - neutral) else 0.0
            timed = not E.params_used(fp.start_s) and (fp.end_s is None or not E.params_used(fp.end_s))
            instant = f.end_s is not None and f.end_s == f.start_s
            self.faults.append((f.index, f, settings, instant, timed))
            self.axes.append(Axis(f"fault{f.index}:present", "bool", severe=1.0))
            if timed:
                # an instant fault has no worst time; a window's worst is the whole run
                self.axes.append(Axis(f"fault{f.index}:start", "unit", severe=None if instant else 0.0))
                if not instant:
                    self.axes.append(Axis(f"fault{f.index}:length", "unit", severe=1.0))
            for name, *_ in settings:
                self.axes.append(Axis(f"fault{f.index}:{name}", "unit", severe=severe.get(name)))
        self.index = {a.name: i for i, a in enumerate(self.axes)}

    @property
    def dims(self) -> int:
        return len(self.axes)

    def params_of(self, u: np.ndarray) -> dict[str, float]:
        params = dict(self.nominal)
        for p, choices in self.params:
            x = float(u[self.index[f"param:{p.name}"]])
            if choices:
                params[p.name] = choices[min(int(x * len(choices)), len(choices) - 1)]
            else:
                params[p.name] = from_unit(p, x)
        return params

    def spec(self, u: np.ndarray, seed: int, run_id: str) -> RunSpec:
        """The pinned RunSpec of point `u`; `seed` gives the run seed and the fault seeds."""
        plan = self.plan
        params = self.params_of(u)
        run_seed = derive_seed(seed, 1)
        nominal = {f.index: f for f in concrete_faults(plan, params, run_seed)}
        entries = []
        duration = plan.duration_s
        for index, _, settings, instant, timed in self.faults:
            if u[self.index[f"fault{index}:present"]] < 0.5:
                continue
            f = nominal[index]
            changes: dict = {"seed": derive_seed(seed, 2, index)}
            if timed:
                start = float(u[self.index[f"fault{index}:start"]]) * duration
                changes["start_s"] = start
                if instant:
                    changes["end_s"] = start
                else:
                    length = float(u[self.index[f"fault{index}:length"]]) * (duration - start)
                    changes["end_s"] = start + length
            new_settings = dict(f.settings)
            for name, lo, hi, integer in settings:
                x = lo + float(u[self.index[f"fault{index}:{name}"]]) * (hi - lo)
                new_settings[name] = float(round(x)) if integer else x
            changes["settings"] = new_settings
            entries.append(C.FaultEntry(f.model_copy(update=changes), plan.faults[index].source or f"fault #{index}"))
        base = RunSpec(plan=plan, params=params, seed=run_seed, faults=[], run_id=run_id)
        return C.rebuild(C.pinned(base), faults=entries)


# ---------------------------------------------------------------- samplers

class UniformSampler:
    name = "random"

    def __init__(self, dims: int, rng: np.random.Generator):
        self.dims, self.rng = dims, rng

    def batch_size(self, default: int, done: int) -> int:
        return default

    def sample(self, n: int) -> np.ndarray:
        return self.rng.random((n, self.dims))

    def update(self, points: np.ndarray, scores: np.ndarray) -> None:
        pass


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
        w = np.log(n + 0.5) - np.log(np.arange(1, n + 1))
        w /= w.sum()
        mu = w @ elite
        sigma = np.sqrt(w @ (elite - mu) ** 2)
        self.mu = SMOOTHING * mu + (1 - SMOOTHING) * self.mu
        self.sigma = np.maximum(SMOOTHING * sigma + (1 - SMOOTHING) * self.sigma, MIN_SIGMA)
        self.p = np.clip(SMOOTHING * mu + (1 - SMOOTHING) * self.p, 0.05, 0.95)
        self.fitted = True


class BayesianSampler:
    """Bayesian optimisation of the failure probability (`--sampler bo`, the default).

    A Gaussian process (scikit-learn; Matern 5/2 with one length scale per axis, plus a
    noise term, since run and fault seeds are drawn afresh for every candidate) models the
    search score (normalised robustness, below 0 = failing) over the unit cube. Each next
    point maximises the model's probability that the score is below 0 (probability of
    improvement over the failure threshold), over uniform candidates and candidates in a
    trust region around the lowest score so far (TuRBO, Eriksson et al. 2019: a box
    stretched along the model's length scales, doubled after successive improvements,
    halved after a run of none). A batch takes the next best candidates at least
    `BO_SPREAD` apart, so parallel workers do not run the same point. Before the first
    fit, one worst case per fault (`worst_cases`: that fault alone, at its severe ends:
    from the start, for the whole run, its settings farthest from neutral; the parameters
    uniform) and a Latin hypercube of `initial` points (scipy.stats.qmc; each axis covered
    in `initial` strata, so a fault is present in half of them) start the model. Why the
    worst cases: a fault's effect grows with its magnitude and window, and where the score
    is flat up to a cliff (`lead_brake_blind`: 7-12 m of clearance for every lidar delay
    under ~140 ms of the 150 searched, then a collision) the model has nothing to climb
    towards the region. Only one point per fault: with every present fault of the
    hypercube at its severe ends (tried first), searches whose failure needs no fault
    (`latency_spike`, `cut_in`) took more runs, the model's first view of the parameters
    being mostly through a severe fault.

    The model sees the score through `warp` (a signed logarithm): robustness spans
    hundreds of metres far from a failure and centimetres near one, and a model of the raw
    score spends its resolution on the far end (a cliff: 0.2 m of clearance inside the
    region, 20-300 m everywhere else); the warp keeps the sign, so 0 stays the threshold.

    The model sees the point as the run sees it: a fault's present axis as 0 or 1, and
    the start, length and settings of an absent fault at 0.5 (they change nothing), so
    a step on a boolean axis and axes that do not matter are not read as noise.

    Why: runs cost 0.05-1 s and a small failure region (under 1 % of the space) needs
    70 or more uniform runs on average; robustness is smooth enough in parameters, fault
    times and magnitudes that a model of it points at the region after a handful of runs.
    The price is the model itself (tens of ms per fitted point, up to `BO_MAX_POINTS`).
    """

    name = "bo"

    def __init__(self, axes: list[Axis], rng: np.random.Generator, jobs: int = 1,
                 fixed: dict[int, float] | None = None, feasible=None):
        self.dims = len(axes)
        self.rng = rng
        self.jobs = max(1, jobs)
        self.fixed = fixed or {}  # axis -> value of every candidate (`BanditSampler`: its fault present)
        # Whether a point satisfies the scenario's `assume`s (None: every point does). The
        # model does not know them: where a failure region borders one it extrapolates
        # across it, and its best candidates, rejected unrun, came back at every ask.
        self.feasible = feasible
        self.initial = max(BO_MIN_INITIAL, self.dims // 2)
        self.bool = np.array([a.kind == "bool" for a in axes], dtype=bool)
        index = {a.name: i for i, a in enumerate(axes)}
        # A fault's other axes -> its present axis (-1: not gated).
        self.gate = np.array([index.get(a.name.split(":")[0] + ":present", -1)
                              if a.name.startswith("fault") and not a.name.endswith(":present") else -1
                              for a in axes], dtype=int)
        self.severe = np.array([np.nan if a.severe is None else a.severe for a in axes], dtype=float)
        self.faults = np.flatnonzero(self.bool & np.isfinite(self.severe))  # present axes with a worst case
        self.started = False
        self.gp = None
        self.points = np.empty((0, self.dims))
        self.scores = np.empty(0)
        self.length = TR_LENGTH_INIT
        self.successes = self.failures = 0
        self.best = math.inf

    def batch_size(self, default: int, done: int) -> int:
        return self.initial + len(self.faults) if done == 0 else self.jobs

    def model_inputs(self, u: np.ndarray) -> np.ndarray:
        """What the model sees of points `u`: booleans as 0/1, an absent fault's axes at 0.5."""
        x = np.array(u, dtype=float, copy=True)
        x[:, self.bool] = (x[:, self.bool] >= 0.5).astype(float)
        gated = np.flatnonzero(self.gate >= 0)
        if len(gated):
            absent = x[:, self.gate[gated]] < 0.5
            x[:, gated] = np.where(absent, 0.5, x[:, gated])
        return x

    def sample(self, n: int) -> np.ndarray:
        if self.gp is None:
            worst = self.worst_cases()[:n] if not self.started else np.empty((0, self.dims))
            self.started = True
            if n <= len(worst):
                return worst
            return np.vstack([worst, qmc.LatinHypercube(self.dims, rng=self.rng).random(n - len(worst))])
        cand = np.vstack([self.rng.random((BO_CANDIDATES, self.dims)), self._trust_region(BO_CANDIDATES)])
        for j, v in self.fixed.items():
            cand[:, j] = v
        with threadpool_limits(1):  # see `update`
            mu, sd = self.gp.predict(self.model_inputs(cand), return_std=True)
        mu = mu * self.y_scale + self.y_mean
        sd = np.maximum(sd * self.y_scale, 1e-12)
        acquisition = norm.logcdf(-mu / sd)  # log P(score < 0): the run fails (log: no ties at 0)
        chosen: list[np.ndarray] = []
        spread = BO_SPREAD * math.sqrt(self.dims)
        for i in np.argsort(-acquisition, kind="stable"):
            if all(np.linalg.norm(cand[i] - c) >= spread for c in chosen) and (
                    self.feasible is None or self.feasible(cand[i])):
                chosen.append(cand[i])
                if len(chosen) == n:
                    break
        while len(chosen) < n:  # every candidate crowded: fill uniformly
            chosen.append(self.rng.random(self.dims))
        return np.array(chosen)

    def worst_cases(self) -> np.ndarray:
        """One point per fault: that fault present at its severe ends (`Axis.severe`: from
        the start, for the whole run, settings farthest from neutral), the other faults
        absent, parameters and axes without a severe end uniform."""
        u = self.rng.random((len(self.faults), self.dims))
        u[:, self.bool] = 0.0
        for k, present in enumerate(self.faults):
            u[k, present] = 1.0
            for j in np.flatnonzero((self.gate == present) & np.isfinite(self.severe)):
                u[k, j] = self.severe[j]
        return u

    def _trust_region(self, n: int) -> np.ndarray:
        """Uniform points in the box around the best point, its sides along the model's
        length scales (mean side `self.length`); a boolean axis flips with probability
        `self.length / 2`."""
        centre = self.points[int(np.argmin(self.scores))]
        scales = np.asarray(self.gp.kernel_.k1.k2.length_scale, dtype=float).reshape(-1)
        if scales.size != self.dims:
            scales = np.full(self.dims, float(scales.mean()))
        w = scales / np.exp(np.mean(np.log(scales)))
        half = 0.5 * self.length * w
        lo, hi = np.clip(centre - half, 0.0, 1.0), np.clip(centre + half, 0.0, 1.0)
        out = lo + (hi - lo) * self.rng.random((n, self.dims))
        flip = self.rng.random((n, self.dims)) < self.length / 2
        for j in np.flatnonzero(self.bool):
            keep = 0.75 if centre[j] >= 0.5 else 0.25
            out[:, j] = np.where(flip[:, j], 1.0 - keep, keep)
        return out

    def update(self, points: np.ndarray, scores: np.ndarray) -> None:
        finite = scores[np.isfinite(scores)]
        if not len(finite):
            return
        # A crash (-inf) is the lowest score seen and a never-violable oracle (+inf) the highest.
        y = warp(np.clip(scores, finite.min() - 1.0, finite.max() + 1.0))
        if self.gp is not None:  # the trust region grows after improvements, shrinks after none
            improved = y.min() < self.best - 1e-3 * max(1.0, abs(self.best))
            self.successes, self.failures = (self.successes + 1, 0) if improved else (0, self.failures + 1)
            if self.successes >= TR_SUCCESSES:
                self.length, self.successes = min(2.0 * self.length, TR_LENGTH_MAX), 0
            elif self.failures >= max(TR_FAILURES, math.ceil(self.dims / self.jobs)):
                self.length, self.failures = self.length / 2.0, 0
                if self.length < TR_LENGTH_MIN:  # collapsed: start again wide
                    self.length = TR_LENGTH_INIT
        self.best = float(y.min())
        keep = np.argsort(y, kind="stable")[:BO_MAX_POINTS]  # the model needs the low end most
        self.points, self.scores = points, y
        x, y = self.model_inputs(points[keep]), y[keep]
        self.y_mean, self.y_scale = float(y.mean()), float(y.std()) or 1.0
        kernel = (ConstantKernel(1.0, (1e-3, 1e3))
                  * Matern(length_scale=np.full(self.dims, 0.5), length_scale_bounds=(0.02, 50.0), nu=2.5)
                  + WhiteKernel(1e-3, (1e-6, 1.0)))
        seed = int(self.rng.integers(2 ** 31))
        # One BLAS thread: the matrices are small (<= BO_MAX_POINTS), and on a loaded machine
        # threaded BLAS made a fit 11x slower (8.2 s against 0.73 s for 20 points, 7 axes).
        with warnings.catch_warnings(), threadpool_limits(1):  # length scales at their bounds are expected
            warnings.simplefilter("ignore", ConvergenceWarning)
            self.gp = GaussianProcessRegressor(kernel, n_restarts_optimizer=1, random_state=seed).fit(
                x, (y - self.y_mean) / self.y_scale)


class BanditSampler:
    """Thompson sampling over which declared fault is present (`--sampler bandit`), with a
    Bayesian optimiser per arm for the rest (docs/falsify-and-shrink.md, "Many faults").

    The arms: each declared fault alone, and no fault. An arm's subspace is the parameters
    plus its fault's axes (present, start, length, settings); each arm has its own
    `BayesianSampler` on that subspace (a few axes, where the single model of `bo` faces
    every fault's axes at once), fitted to every run with at most one fault (the other
    arms' runs tell it what the parameters do without its fault), its candidates with its
    fault present (`fixed`). A point belongs to the arm its present axes say. Faults
    together are no arm's: a failure that needs two faults at once is `bo`'s to find (an
    arm of uniform points over the whole space was tried: its points often held the
    culprit, so it drew pulls away from the culprit's own arm, and it was dropped).

    Each arm is pulled once first, a fault arm at its fault's worst case (the severe end
    of every axis that has one, parameters uniform; `bo` starts the same way), and until
    an arm has had `BANDIT_MIN_MODEL` pulls its fault stays there, the parameters from the
    arm's model once it has one: a failure that needs the fault is likeliest at its severe
    end, and the other arms' runs show where the parameters come near failing (with
    uniform parameters, the stuck command's four worst cases of `stuck_many_faults` fell at
    long gaps and three seeds of 20 found nothing in 150 runs).

    Then each run goes to the arm whose Thompson draw gives the highest probability of
    failing: the arm's (warped, `warp`) scores are modelled as normal with unknown mean and
    variance (normal-inverse-gamma posterior; the prior's centre and spread are those of
    all scores so far, worth one run), and the arm's value is P(score < 0) under a drawn
    mean and variance. An arm whose runs come near the threshold, or spread across it, is
    pulled more; an arm whose runs stay far from it is still drawn now and then. Inside
    the arm, its model picks the point. Points asked for again before any result (an
    `assume` rejected the last ones) are uniform in their arm: the model would propose the
    same corner again.

    Why: with several faults declared, `bo` spends one run per fault on worst cases and a
    hypercube of half as many runs as the axes (13 and 16 on the many-fault scenarios)
    before its model, and the model fits one length scale per axis of every fault from a
    few tens of points; a failure that needs one fault lives in that fault's slice of the
    space, which the bandit searches with a model of a few axes.
    """

    name = "bandit"

    def __init__(self, axes: list[Axis], rng: np.random.Generator, jobs: int = 1, feasible=None):
        self.dims = len(axes)
        self.rng = rng
        self.jobs = max(1, jobs)
        names = [a.name for a in axes]
        self.present = np.array([i for i, n in enumerate(names) if n.endswith(":present")], dtype=int)
        params = [i for i, n in enumerate(names) if n.startswith("param:")]
        # (name, present axis or -1, subspace axes). The fault arms come first: the first runs are their worst cases, in declaration order.
        self.arms: list[tuple[str, int, list[int]]] = []
        for p in self.present:
            prefix = names[p].split(":")[0] + ":"
            self.arms.append((prefix[:-1], int(p), params + [i for i, n in enumerate(names) if n.startswith(prefix)]))
        self.none = len(self.arms)
        self.arms.append(("none", -1, params))
        # A fault arm's model has the fault's present axis, fixed at 1 in its candidates.
        self.models = [BayesianSampler([axes[i] for i in sub], rng, jobs,
                                       fixed={sub.index(present): 1.0} if present >= 0 else None,
                                       feasible=_embedded(feasible, self.dims, sub)) if sub else None
                       for _, present, sub in self.arms]
        self.severe = np.array([np.nan if a.severe is None else a.severe for a in axes], dtype=float)
        self.pulls = np.zeros(len(self.arms), dtype=int)  # points drawn per arm (by the arm drawn for)
        self.fitted = [-1] * len(self.arms)  # the runs the arm's model was last fitted to
        self.points, self.scores = np.empty((0, self.dims)), np.empty(0)
        self.asked = False  # points handed out since the last update
        self.y = np.empty(0)  # warped scores so far
        self.arm_of = np.empty(0, dtype=int)

    def batch_size(self, default: int, done: int) -> int:
        return len(self.arms) if done == 0 else self.jobs

    def classify(self, points: np.ndarray) -> np.ndarray:
        """The arm of each point, by its present axes (-1: several faults, no arm's)."""
        if not len(self.present):
            return np.full(len(points), self.none, dtype=int)
        on = np.asarray(points)[:, self.present] >= 0.5
        count = on.sum(axis=1)
        return np.where(count == 0, self.none, np.where(count == 1, np.argmax(on, axis=1), -1))

    def choose(self) -> int:
        """The next arm: the first never pulled, else the best Thompson draw."""
        unpulled = np.flatnonzero(self.pulls == 0)
        if len(unpulled):
            return int(unpulled[0])
        values = [self._draw(self.y[self.arm_of == k]) for k in range(len(self.arms))]
        return int(np.argmax(values))

    def _draw(self, y: np.ndarray) -> float:
        """log P(score < 0) under a mean and variance drawn from the arm's normal-inverse-gamma
        posterior (prior: all scores' mean and variance, worth one run)."""
        m0 = float(self.y.mean()) if len(self.y) else 0.0
        v0 = float(self.y.var()) if len(self.y) > 1 and self.y.var() > 0 else 1.0
        kappa0, alpha0 = 1.0, 2.0
        beta0 = v0 * (alpha0 - 1.0)  # the prior's expected variance is v0
        n = len(y)
        mean = float(y.mean()) if n else m0
        kappa, alpha = kappa0 + n, alpha0 + n / 2.0
        beta = beta0 + 0.5 * float(((y - mean) ** 2).sum()) + kappa0 * n * (mean - m0) ** 2 / (2.0 * kappa)
        m = (kappa0 * m0 + n * mean) / kappa
        var = beta / self.rng.gamma(alpha)  # inverse gamma
        mu = self.rng.normal(m, math.sqrt(var / kappa))
        return float(norm.logcdf(-mu / math.sqrt(var)))

    def sample(self, n: int) -> np.ndarray:
        # Asked again before any result: the last points broke an `assume` and were never
        # run. A model would propose the same corner again, so these are uniform in the arm.
        retry, self.asked = self.asked, True
        arms = []
        for _ in range(n):
            k = self.choose()
            self.pulls[k] += 1
            arms.append((k, self.pulls[k] <= BANDIT_MIN_MODEL))
        out = self.rng.random((n, self.dims))  # axes outside an arm's subspace change nothing
        out[:, self.present] = 0.0
        for k in sorted({k for k, _ in arms}):
            _, present, sub = self.arms[k]
            rows = [i for i, a in enumerate(arms) if a[0] == k]
            if present >= 0:
                out[rows, present] = 1.0
            if not sub:
                continue
            early = [i for i in rows if arms[i][1]]
            if early:  # the fault's worst case; the parameters uniform, or the model's once it has one
                self._fit(k)
                model, severe = self.models[k], self.severe[sub]
                if model.gp is None or retry:
                    for i in early:
                        out[i, sub] = np.where(np.isfinite(severe), severe, out[i, sub])
                else:
                    free = model.fixed
                    model.fixed = {**free, **{int(j): float(severe[j]) for j in np.flatnonzero(np.isfinite(severe))}}
                    out[np.ix_(early, sub)] = model.sample(len(early))
                    model.fixed = free
            later = [i for i in rows if not arms[i][1]]
            if later and not retry:
                self._fit(k)
                out[np.ix_(later, sub)] = self.models[k].sample(len(later))
        return out

    def _fit(self, k: int) -> None:
        """Fit arm `k`'s model to the runs so far, if it has not seen them: a fault arm's to
        every run with no other fault (the rest tell it what the parameters do without its
        fault), the no-fault arm's to its own."""
        arm = self.arm_of
        use = np.flatnonzero(arm == k) if k == self.none else np.flatnonzero(arm >= 0)
        if self.models[k] is None or len(use) < BANDIT_MIN_MODEL or len(use) == self.fitted[k]:
            return
        self.fitted[k] = len(use)
        self.models[k].update(self.points[use][:, self.arms[k][2]], self.scores[use])

    def update(self, points: np.ndarray, scores: np.ndarray) -> None:
        self.asked = False
        finite = scores[np.isfinite(scores)]
        if not len(finite):
            return
        self.points, self.scores = points, scores
        self.y = warp(np.clip(scores, finite.min() - 1.0, finite.max() + 1.0))
        self.arm_of = self.classify(points)
        self.fitted = [-1] * len(self.arms)  # scores change when an oracle is falsified: refit when pulled


def _embedded(feasible, dims: int, sub: list[int]):
    """`feasible` of a full point, as a test of an arm's subspace points: `assume`s read
    parameters only, and every arm's subspace has every parameter axis."""
    if feasible is None:
        return None

    def test(v: np.ndarray) -> bool:
        u = np.full(dims, 0.5)
        u[sub] = v
        return feasible(u)
    return test


def warp(score: np.ndarray) -> np.ndarray:
    """Signed logarithm of scores (`BayesianSampler`): monotone, odd, 0 at 0; resolution
    near 0 (a failure's boundary), compression far from it."""
    score = np.asarray(score, dtype=float)
    return np.sign(score) * np.log1p(np.abs(score) / WARP_SCALE)


# ---------------------------------------------------------------- the search

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

    def describe(self) -> str:
        return f"{self.oracle} [{self.mode}]"


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

    def print_text(self) -> None:
        first = f", first after {self.first_failure_run} run(s)" if self.first_failure_run else ""
        print(f"falsify {self.scenario} ({self.sampler}): {self.runs} runs in {self.seconds:.1f} s, "
              f"{len(self.failures)} distinct failure(s){first}; {self.shrink_simulations} shrink simulations")
        if self.ended_early:
            print(f"  ended early: {self.ended_early}")
        for i, f in enumerate(self.failures, 1):
            print(f"  {i}. {f.describe()}: {f.count} failing run(s), first at run {f.first_run}, "
                  f"worst robustness {f.worst_robustness:.3g}")
            print(f"     origin: {f.origin}")
        if not self.failures:
            worst = ", ".join(f"{k} {v:.3g}" for k, v in sorted(self.best_robustness.items()))
            print(f"  no failure; lowest robustness per oracle: {worst}")


class Falsifier:
    def __init__(self, plan: ScenarioPlan, *, seed: int = 0, batch: int = 16, jobs: int = 1,
                 sampler: str = "bo", cache: RunCache | None = None, log=None):
        self.plan = plan
        self.space = SearchSpace(plan)
        self.seed = seed
        self.batch = max(2, batch)
        self.jobs = jobs
        self.cache = cache or RunCache()
        self.log = log or (lambda msg: None)
        rng = np.random.default_rng(derive_seed(seed, 31337))
        if sampler not in SAMPLERS:
            raise ValueError(f"unknown sampler {sampler!r}: one of {', '.join(SAMPLERS)}")
        feasible = (lambda u: not violated_assumptions(plan, self.space.params_of(u))) if plan.assumptions else None
        self.sampler = {"bo": lambda: BayesianSampler(self.space.axes, rng, jobs, feasible=feasible),
                        "bandit": lambda: BanditSampler(self.space.axes, rng, jobs, feasible),
                        "cem": lambda: CrossEntropySampler(self.space.axes, rng),
                        "random": lambda: UniformSampler(self.space.dims, rng)}[sampler]()
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
                                        max_simulations=shrink_simulations).run()
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
        window = (f"from {_short(f.start_s)} s" if f.end_s is None else
                  f"at {_short(f.start_s)} s" if f.end_s == f.start_s else
                  f"during [{_short(f.start_s)} s, {_short(f.end_s)} s]")
        parts.append(f"{f.kind} {f.target} {settings} {window}".replace("  ", " "))
    for k, v in sorted(spec.params.items()):
        if k in nominal and v != nominal[k]:
            parts.append(f"{k} = {_short(v)} (nominal {_short(nominal[k])})")
    return "; ".join(parts) if parts else "nominal scenario (no fault, nominal parameters)"


def _short(v) -> str:
    return f"{v:.4g}" if isinstance(v, float) else str(v)
