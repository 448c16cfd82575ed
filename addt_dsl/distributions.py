"""Parameter distributions: one registered piece per `dist` keyword, each an inverse
cumulative distribution over the parameter's range.

A sampler (random, Halton, Latin hypercube) draws u in [0, 1) per parameter; the
parameter's distribution maps u to a value (`Distribution.value(p, u)`). A range `in [lo,
hi]` truncates every continuous distribution to it (the density renormalised inside the
range, as OpenSCENARIO's `Range` of a stochastic distribution), so no value piles up at a
bound. The compiler reads each entry's settings; docs/language.md's table is this one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from statistics import NormalDist
from typing import Callable

from addt_dsl.plan import ParamPlan

_STD = NormalDist()
MAX_POISSON_MEAN = 500.0  # exp(-mean) stays a normal double (docs/limits.md)


@dataclass(frozen=True)
class Distribution:
    keyword: str
    doc: str
    required: tuple[str, ...]  # settings it needs (beyond the domain)
    optional: tuple[str, ...]
    value: Callable[[ParamPlan, float], float]
    needs_range: bool = False  # a bounded density: `in [lo, hi]` is required


DISTRIBUTIONS: dict[str, Distribution] = {}


def register(d: Distribution) -> Distribution:
    DISTRIBUTIONS[d.keyword] = d
    return d


def _clip_u(u: float) -> float:
    return min(max(u, 1e-12), 1.0 - 1e-12)


def _bounds(p: ParamPlan) -> tuple[float, float]:
    return (p.low if p.low is not None else -math.inf, p.high if p.high is not None else math.inf)


def _truncated(u: float, cdf: Callable[[float], float], ppf: Callable[[float], float], lo: float, hi: float) -> float:
    """The inverse CDF of a distribution truncated to [lo, hi] at u: ppf(F(lo) + u (F(hi) - F(lo)))."""
    f_lo = cdf(lo) if math.isfinite(lo) else 0.0
    f_hi = cdf(hi) if math.isfinite(hi) else 1.0
    if not f_hi > f_lo:  # the range lies where the density is below double precision: its nearer end
        return lo if f_lo >= 1.0 - 1e-15 or not math.isfinite(hi) else hi
    return min(max(ppf(_clip_u(f_lo + u * (f_hi - f_lo))), lo), hi)


def _uniform(p: ParamPlan, u: float) -> float:
    lo = p.low if p.low is not None else p.default
    hi = p.high if p.high is not None else p.default
    return lo + (hi - lo) * u


def _normal(p: ParamPlan, u: float) -> float:
    mean = p.mean if p.mean is not None else p.default
    sd = p.sd or 0.0
    lo, hi = _bounds(p)
    if sd <= 0.0:
        return min(max(mean, lo), hi)
    return _truncated(u, lambda x: _STD.cdf((x - mean) / sd), lambda q: mean + sd * _STD.inv_cdf(q), lo, hi)


def lognormal_mu_sigma(mean: float, sd: float) -> tuple[float, float]:
    """The underlying normal's (mu, sigma) of a log-normal with this mean and sd."""
    sigma2 = math.log1p((sd / mean) ** 2)
    return math.log(mean) - sigma2 / 2.0, math.sqrt(sigma2)


def _lognormal(p: ParamPlan, u: float) -> float:
    mean = p.mean if p.mean is not None else p.default
    mu, sigma = lognormal_mu_sigma(mean, p.sd)
    lo, hi = _bounds(p)

    def cdf(x: float) -> float:
        return 0.0 if x <= 0.0 else _STD.cdf((math.log(x) - mu) / sigma)

    return _truncated(u, cdf, lambda q: math.exp(mu + sigma * _STD.inv_cdf(q)), max(lo, 0.0), hi)


def _poisson(p: ParamPlan, u: float) -> float:
    """The smallest k in the range with P(K <= k | lo <= K <= hi) > u (pmf by recurrence)."""
    lam = p.mean if p.mean is not None else p.default
    lo, hi = _bounds(p)
    k_lo = max(0, math.ceil(lo)) if math.isfinite(lo) else 0
    k_hi = math.floor(hi) if math.isfinite(hi) else math.inf
    pmf, k, cum = math.exp(-lam), 0, 0.0
    masses: list[tuple[int, float]] = []
    tail_end = max(k_lo, lam + 40.0 * math.sqrt(lam) + 40.0)  # beyond it the mass is below 1e-300
    while k <= min(k_hi, tail_end):
        if k >= k_lo:
            masses.append((k, pmf))
            cum += pmf
        k += 1
        pmf *= lam / k
    if cum <= 0.0:
        return float(k_lo)
    target = u * cum
    run = 0.0
    for k, m in masses:
        run += m
        if run > target:
            return float(k)
    return float(masses[-1][0])


def _histogram(p: ParamPlan, u: float) -> float:
    """Piecewise uniform: bin i spans [bins[i], bins[i+1]) with probability weights[i] / sum."""
    total = sum(p.weights)
    target = u * total
    run = 0.0
    for i, w in enumerate(p.weights):
        if w > 0.0 and run + w > target:
            a, b = p.bins[i], p.bins[i + 1]
            return a + (b - a) * (target - run) / w
        run += w
    last = max(i for i, w in enumerate(p.weights) if w > 0.0)
    return p.bins[last + 1]


def _choice(p: ParamPlan, u: float) -> float:
    if not p.weights:
        return p.choices[min(int(u * len(p.choices)), len(p.choices) - 1)]
    target = u * sum(p.weights)
    run = 0.0
    for c, w in zip(p.choices, p.weights):
        run += w
        if w > 0.0 and run > target:
            return c
    return next(c for c, w in zip(reversed(p.choices), reversed(p.weights)) if w > 0.0)


register(Distribution("uniform", "uniform over the range (the default for a range)", (), (), _uniform))
register(Distribution("normal", "normal with `sd` and `mean` (default: the parameter's default), truncated to "
                                "the range", ("sd",), ("mean",), _normal))
register(Distribution("lognormal", "log-normal whose own `mean` (default: the parameter's default) and `sd` are "
                                   "given, truncated to the range; values are positive", ("sd",), ("mean",),
                      _lognormal))
register(Distribution("poisson", "Poisson counts 0, 1, 2, ... with `mean` (default: the parameter's default), "
                                 "truncated to the range; dimensionless, whole numbers", (), ("mean",), _poisson))
register(Distribution("histogram", "piecewise uniform: `bins [e0, e1, ..., en]` (edges inside the range) with "
                                   "`weights [w1, ..., wn]`", ("bins", "weights"), (), _histogram, needs_range=True))
register(Distribution("choice", "one of the listed values (`in [a, b, c]`), equally likely or in proportion to "
                                "`weights [...]`", (), ("weights",), _choice))


def from_unit(p: ParamPlan, u: float) -> float:
    """The value of parameter `p` at u in [0, 1) of its distribution. An `integer`
    parameter takes whole numbers: a uniform range each of its integers equally likely,
    another distribution its value rounded (into the range)."""
    if p.choices and p.distribution == "choice":
        return _choice(p, u)
    if p.integer and p.distribution == "uniform" and p.low is not None and p.high is not None:
        k_lo, k_hi = math.ceil(p.low), math.floor(p.high)
        return float(min(k_lo + int(u * (k_hi - k_lo + 1)), k_hi))
    value = DISTRIBUTIONS[p.distribution].value(p, u)
    if p.integer:
        lo, hi = _bounds(p)
        value = float(min(max(round(value), math.ceil(lo)), math.floor(hi)))
    return value


def markdown_table() -> str:
    rows = ["| `dist` | settings | draws |", "|--------|----------|-------|"]
    for d in DISTRIBUTIONS.values():
        settings = ", ".join([*(f"`{s}`" for s in d.required), *(f"[`{s}`]" for s in d.optional)]) or "-"
        rows.append(f"| `{d.keyword}` | {settings} | {d.doc} |")
    return "\n".join(rows)


if __name__ == "__main__":
    print(markdown_table())
