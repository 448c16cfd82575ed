"""Thompson sampling over which declared fault is present, Bayesian optimisation inside
(`--sampler bandit`, for schedules of many faults)."""

from __future__ import annotations

import math

import numpy as np
from scipy.stats import norm

from addt_dsl.search.samplers import SamplerContext
from addt_dsl.search.samplers.bo import BayesianSampler, warp
from addt_dsl.search.space import Axis

BANDIT_MIN_MODEL = 4  # pulls of a bandit arm with its fault at the worst case; runs before an arm's model


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
        # (name, present axis or -1, subspace axes). The fault arms come first: the first runs
        # are their worst cases, in declaration order.
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

    @classmethod
    def create(cls, ctx: SamplerContext) -> BanditSampler:
        return cls(ctx.axes, ctx.rng, ctx.jobs, ctx.feasible)

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

