"""Bayesian optimisation of the failure probability (`--sampler bo`, the default)."""

from __future__ import annotations

import math
import warnings

import numpy as np
from scipy.stats import norm, qmc
from sklearn.exceptions import ConvergenceWarning
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import ConstantKernel, Matern, WhiteKernel
from threadpoolctl import threadpool_limits

from addt_dsl.search.samplers import SamplerContext
from addt_dsl.search.space import Axis

BO_MIN_INITIAL = 4  # uniform points before the first model (at least half the axes)
BO_CANDIDATES = 2000  # uniform candidates per choice, and as many around the best points
# Trust region (TuRBO): mean side of the box around the best point, as a fraction of the cube
TR_LENGTH_INIT, TR_LENGTH_MIN, TR_LENGTH_MAX = 0.4, 0.05, 0.8
TR_SUCCESSES, TR_FAILURES = 2, 3  # improving batches to double it; batches without to halve it
BO_SPREAD = 0.05  # minimum distance between the points of one batch, per sqrt(axes)
BO_MAX_POINTS = 200  # points the model is fitted to (the lowest scores)
WARP_SCALE = 0.05  # scores (robustness / its median size) are modelled as sign * log(1 + |score| / WARP_SCALE)


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

    @classmethod
    def create(cls, ctx: SamplerContext) -> BayesianSampler:
        return cls(ctx.axes, ctx.rng, ctx.jobs, feasible=ctx.feasible)

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



def warp(score: np.ndarray) -> np.ndarray:
    """Signed logarithm of scores (`BayesianSampler`): monotone, odd, 0 at 0; resolution
    near 0 (a failure's boundary), compression far from it."""
    score = np.asarray(score, dtype=float)
    return np.sign(score) * np.log1p(np.abs(score) / WARP_SCALE)

