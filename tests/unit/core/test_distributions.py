"""Parameter distributions (addt_dsl/distributions.py): each one's draws against its
textbook law, truncation to the range, integer parameters, the compiler's checks and the
printer's round trip."""

from __future__ import annotations

import collections
import math
import statistics

import pytest

from addt_dsl.compiler import compile_source
from addt_dsl.distributions import DISTRIBUTIONS, from_unit, lognormal_mu_sigma
from addt_dsl.plan import ParamPlan
from addt_dsl.printer import print_plan
from addt_dsl.sweep import expand

N = 4000
GRID = [(i + 0.5) / N for i in range(N)]  # a stratified u: sample moments converge fast


def draws(**fields) -> list[float]:
    p = ParamPlan(name="x", dimension="dimensionless", default=fields.pop("default", 1.0), **fields)
    return [from_unit(p, u) for u in GRID]


def test_truncated_normal_has_the_truncated_mean_and_nothing_on_the_bound():
    xs = draws(default=0.0, low=-1.0, high=3.0, distribution="normal", sd=1.0)
    # E[X | -1 <= X <= 3] for a standard normal: (phi(-1) - phi(3)) / (Phi(3) - Phi(-1)) = 0.2801.
    phi = lambda z: math.exp(-z * z / 2) / math.sqrt(2 * math.pi)  # noqa: E731
    nd = statistics.NormalDist()
    expected = (phi(-1) - phi(3)) / (nd.cdf(3) - nd.cdf(-1))
    assert statistics.fmean(xs) == pytest.approx(expected, abs=2e-3)
    assert min(xs) > -1.0 and max(xs) < 3.0


def test_lognormal_mean_and_sd_are_its_own():
    xs = draws(default=20.0, low=1e-3, high=1e3, distribution="lognormal", mean=20.0, sd=4.0)
    assert statistics.fmean(xs) == pytest.approx(20.0, rel=2e-3)
    assert statistics.pstdev(xs) == pytest.approx(4.0, rel=2e-2)
    mu, sigma = lognormal_mu_sigma(20.0, 4.0)
    assert statistics.median(xs) == pytest.approx(math.exp(mu), rel=1e-3)  # the median is e^mu
    assert sigma == pytest.approx(math.sqrt(math.log(1 + 0.04)))


def test_poisson_frequencies_are_the_pmf():
    xs = draws(default=2.0, low=0.0, high=30.0, distribution="poisson", mean=2.0, integer=True)
    counts = collections.Counter(xs)
    for k in range(6):
        assert counts[float(k)] / N == pytest.approx(math.exp(-2) * 2 ** k / math.factorial(k), abs=1.5 / N)


def test_histogram_is_piecewise_uniform():
    xs = draws(default=5.0, low=0.0, high=10.0, distribution="histogram", bins=[0.0, 2.0, 10.0], weights=[3.0, 1.0])
    assert sum(x < 2.0 for x in xs) / N == pytest.approx(0.75, abs=1 / N)
    low = [x for x in xs if x < 2.0]
    assert statistics.fmean(low) == pytest.approx(1.0, abs=2e-3)


def test_weighted_choice_and_integer_uniform():
    xs = draws(default=-1.0, choices=[-1.0, -2.0, -3.0], weights=[2.0, 1.0, 1.0], distribution="choice",
               low=-3.0, high=-1.0)
    assert collections.Counter(xs) == {-1.0: N // 2, -2.0: N // 4, -3.0: N // 4}
    ks = draws(default=2.0, low=1.0, high=4.0, integer=True)
    assert collections.Counter(ks) == {1.0: N // 4, 2.0: N // 4, 3.0: N // 4, 4.0: N // 4}


SCENE = """
scenario dists {
  duration 1 s
  road r { line length 500 m }
  PARAM
  ego car on r lane -1 at 10 m + x * 1 m speed 10 m/s
  sweep {
    random 20 seed 3
  }
}
"""


@pytest.mark.parametrize("line", [
    "param x = 30 in [10, 80] dist lognormal mean 30 sd 10",
    "param x = 2 in [0, 8] dist poisson mean 2",
    "param x = 10 in [5, 20] dist histogram bins [5, 10, 20] weights [3, 1]",
    "param x = 1 in [1, 2, 3] weights [2, 1, 1] integer true",
    "param x = 2 in [1, 4] dist normal sd 1 integer true",
])
def test_each_distribution_prints_and_reads_back_with_the_same_runs(line):
    got = compile_source(SCENE.replace("PARAM", line), "d.addt")
    assert got.ok, [str(d) for d in got.diagnostics]
    again = compile_source(print_plan(got.plan), "again.addt")
    assert again.ok, [str(d) for d in again.diagnostics]
    assert again.plan.params == got.plan.params
    assert [s.params for s in expand(again.plan).specs] == [s.params for s in expand(got.plan).specs]


@pytest.mark.parametrize("line, code", [
    ("param x = 30 in [10, 80] dist lognormal mean 30", "E0105"),  # no sd
    ("param x = 30 in [10, 80] dist lognormal mean -3 sd 1", "E0301"),
    ("param x = 2 m in [0 m, 8 m] dist poisson", "E0204"),  # a length does not count
    ("param x = 2 in [0, 8] dist poisson mean 900", "E0301"),
    ("param x = 10 dist histogram bins [5, 10, 20] weights [3, 1]", "E0105"),  # no range
    ("param x = 10 in [5, 20] dist histogram bins [5, 10, 20] weights [3]", "E0204"),
    ("param x = 10 in [5, 20] dist histogram bins [5, 30] weights [1]", "E0301"),
    ("param x = 10 in [5, 20] dist histogram bins [5, 20, 10] weights [1, 1]", "E0204"),
    ("param x = 1 in [1, 2, 3] weights [2, 1]", "E0204"),
    ("param x = 1 in [1, 2, 3] weights [-1, 1, 1]", "E0301"),
    ("param x = 1 in [1, 2] dist gamma", "E0204"),
])
def test_bad_distributions_are_diagnostics(line, code):
    got = compile_source(SCENE.replace("PARAM", line), "d.addt")
    assert not got.ok
    assert code in [d.code for d in got.diagnostics], [str(d) for d in got.diagnostics]


def test_the_language_docs_table_is_the_registry():
    from addt_dsl.distributions import markdown_table
    from tests.conftest import ROOT

    text = (ROOT / "docs" / "language.md").read_text()
    assert markdown_table() in text
    assert all(f"| `{name}` |" in markdown_table() for name in DISTRIBUTIONS)
