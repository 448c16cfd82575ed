"""`addtc import` of a logical scenario: an OpenSCENARIO ParameterValueDistribution and the
template it names (esmini's acc-test.xosc) become one `.addt` whose sweep is the
distribution; what the language cannot draw is refused with a diagnostic naming it."""

from __future__ import annotations

import math
import re
import shutil
import statistics
import time

import pytest

from addt_dsl.cli import main
from addt_dsl.expr import eval_param_expr
from addt_dsl.interop.openscenario.importer import import_xosc
from addt_dsl.sweep import expand
from tests.conftest import ROOT

ESMINI = ROOT / "tests" / "data" / "esmini"
HEAD = ('<?xml version="1.0" encoding="UTF-8"?>\n<OpenSCENARIO>\n'
        '  <FileHeader revMajor="1" revMinor="2" date="2026-12-06T00:00:00" description="acc variation" author="t"/>\n'
        '  <ParameterValueDistribution>\n    <ScenarioFile filepath="acc-test.xosc"/>\n')
TAIL = "  </ParameterValueDistribution>\n</OpenSCENARIO>\n"


@pytest.fixture
def corpus(tmp_path):
    """A copy of the esmini corpus: distribution files go next to acc-test.xosc."""
    shutil.copytree(ESMINI, tmp_path / "esmini")
    return tmp_path / "esmini"


def write(corpus, body: str, name: str = "variation.xosc"):
    path = corpus / "xosc" / name
    path.write_text(HEAD + body + TAIL)
    return path


def imported(corpus, body: str):
    return import_xosc(write(corpus, body), root=corpus)


def errors(got) -> list[str]:
    return [f"{d.code} {d.message}" for d in got.diagnostics if d.is_error]


def single(name: str, inner: str) -> str:
    return f'<DeterministicSingleParameterDistribution parameterName="{name}">{inner}' \
           "</DeterministicSingleParameterDistribution>\n"


def stochastic(runs: int, seed, dists: dict[str, str]) -> str:
    seed_attr = f' randomSeed="{seed}"' if seed is not None else ""
    body = "".join(f'<StochasticDistribution parameterName="{n}">{d}</StochasticDistribution>\n'
                   for n, d in dists.items())
    return f'<Stochastic numberOfTestRuns="{runs}"{seed_attr}>\n{body}</Stochastic>\n'


def runs_of(got, *names):
    return [tuple(s.params[n] for n in names) for s in expand(got.plan).specs]


def test_range_and_set_multiply(corpus):
    # EgoS: 10, 15, 20 (stepWidth 5, the upper limit included); TargetS: a set: 3 x 2 runs.
    got = imported(corpus, "<Deterministic>\n"
                   + single("EgoS", '<DistributionRange stepWidth="5"><Range lowerLimit="10" upperLimit="20"/>'
                                    "</DistributionRange>")
                   + single("TargetS", '<DistributionSet><Element value="80"/><Element value="120"/></DistributionSet>')
                   + "</Deterministic>\n")
    assert got.text is not None, errors(got)
    assert "grid EgoS in [10 m, 15 m, 20 m]" in got.text and "grid TargetS in [80 m, 120 m]" in got.text
    runs = runs_of(got, "EgoS", "TargetS")
    assert len(runs) == 6 and set(runs) == {(e, t) for e in (10.0, 15.0, 20.0) for t in (80.0, 120.0)}
    # The parameters keep their names and their dimension from where acc-test uses them
    # (a LanePosition's s: a length).
    assert {p.name: p.dimension for p in got.plan.params} == {"EgoS": "length", "TargetS": "length"}


def test_value_sets_are_listed_combinations(corpus):
    # Three sets, not 3 x 3 runs; the third leaves TargetS out: its declared value (100 m).
    got = imported(corpus, "<Deterministic>\n<DeterministicMultiParameterDistribution><ValueSetDistribution>"
                   '<ParameterValueSet><ParameterAssignment parameterRef="EgoS" value="10"/>'
                   '<ParameterAssignment parameterRef="TargetS" value="60"/></ParameterValueSet>'
                   '<ParameterValueSet><ParameterAssignment parameterRef="EgoS" value="30"/>'
                   '<ParameterAssignment parameterRef="TargetS" value="90"/></ParameterValueSet>'
                   '<ParameterValueSet><ParameterAssignment parameterRef="EgoS" value="50"/></ParameterValueSet>'
                   "</ValueSetDistribution></DeterministicMultiParameterDistribution>\n</Deterministic>\n")
    assert got.text is not None, errors(got)
    assert "cases EgoS in [10 m, 30 m, 50 m], TargetS in [60 m, 90 m, 100 m]" in got.text
    assert runs_of(got, "EgoS", "TargetS") == [(10.0, 60.0), (30.0, 90.0), (50.0, 100.0)]


def test_a_parameter_used_as_km_per_h_stays_km_per_h(corpus):
    # acc-test sets the ego's speed to ${$EgoSpeed / 3.6}: EgoSpeed is in km/h. The sweep's
    # 90 and 120 are 25 and 33.3 m/s, the default 120 km/h too, and the ego's speed reads
    # the parameter itself; a uniform draw in [90, 108] km/h is in [25, 30] m/s.
    got = imported(corpus, "<Deterministic>\n" + single(
        "EgoSpeed", '<DistributionSet><Element value="90"/><Element value="120"/></DistributionSet>')
        + "</Deterministic>\n")
    assert got.text is not None, errors(got)
    (p,) = [p for p in got.plan.params if p.name == "EgoSpeed"]
    assert p.dimension == "speed" and p.default == pytest.approx(120 / 3.6)
    specs = expand(got.plan).specs
    assert [s.params["EgoSpeed"] for s in specs] == pytest.approx([25.0, 120 / 3.6])
    assert [eval_param_expr(got.plan.ego.speed, s.params) for s in specs] == pytest.approx([25.0, 120 / 3.6])
    got = imported(corpus, stochastic(50, 3, {
        "EgoSpeed": '<UniformDistribution><Range lowerLimit="90" upperLimit="108"/></UniformDistribution>'}))
    assert got.text is not None, errors(got)
    drawn = [s.params["EgoSpeed"] for s in expand(got.plan).specs]
    assert min(drawn) >= 25.0 and max(drawn) <= 30.0 + 1e-12 and max(drawn) - min(drawn) > 3.0


def test_a_fractional_step_reaches_its_upper_limit(corpus):
    # 0.3 / 0.1 is 2.9999999999999996 in floating point: the range still has its 4 values.
    got = imported(corpus, "<Deterministic>\n" + single(
        "EgoS", '<DistributionRange stepWidth="0.1"><Range lowerLimit="11" upperLimit="11.3"/>'
                "</DistributionRange>") + "</Deterministic>\n")
    assert got.text is not None, errors(got)
    values = [r[0] for r in runs_of(got, "EgoS")]
    assert len(values) == 4 and values[0] == 11.0 and math.isclose(values[-1], 11.3) and values[-1] <= 11.3


NORMAL_AND_WEIGHTED = {"EgoS": '<NormalDistribution expectedValue="20" variance="4"/>',
                       "TargetS": '<ProbabilityDistributionSet><Element value="80" weight="0.25"/>'
                                  '<Element value="120" weight="0.75"/></ProbabilityDistributionSet>'}


def test_normal_and_weighted_set_draws_follow_the_standard_parameters(corpus):
    # 2000 draws with seed 42: a normal N(20, variance 4), so sd 2; a set weighted 1:3.
    got = imported(corpus, stochastic(2000, 42, NORMAL_AND_WEIGHTED))
    assert got.text is not None, errors(got)
    assert "random 2000 seed 42" in got.text and "dist normal mean 20 m sd 2 m" in got.text
    runs = runs_of(got, "EgoS", "TargetS")
    assert len(runs) == 2000
    ego = [r[0] for r in runs]
    # Standard errors: mean 2/sqrt(2000) = 0.045, sd about 0.032; 5 of them each way.
    assert abs(statistics.fmean(ego) - 20.0) < 0.23 and abs(statistics.stdev(ego) - 2.0) < 0.16
    share = sum(r[1] == 80.0 for r in runs) / len(runs)
    assert {r[1] for r in runs} == {80.0, 120.0} and abs(share - 0.25) < 5 * math.sqrt(0.25 * 0.75 / 2000)
    # The seed is the sweep's: the same file gives the same runs, another seed others.
    assert runs == runs_of(imported(corpus, stochastic(2000, 42, NORMAL_AND_WEIGHTED)), "EgoS", "TargetS")
    assert runs != runs_of(imported(corpus, stochastic(2000, 43, NORMAL_AND_WEIGHTED)), "EgoS", "TargetS")


def test_uniform_and_an_even_histogram_draw_uniformly(corpus):
    # A uniform in [5, 7]; a histogram of two equal bins [10, 12), [12, 14]: uniform in [10, 14].
    got = imported(corpus, stochastic(2000, None, {
        "EgoS": '<UniformDistribution><Range lowerLimit="5" upperLimit="7"/></UniformDistribution>',
        "TargetS": '<Histogram><Bin weight="1"><Range lowerLimit="10" upperLimit="12"/></Bin>'
                   '<Bin weight="1"><Range lowerLimit="12" upperLimit="14"/></Bin></Histogram>'}))
    assert got.text is not None, errors(got)
    assert any(d.code == "W0802" and "no randomSeed: seed 0" in d.message for d in got.diagnostics)
    runs = runs_of(got, "EgoS", "TargetS")
    # Uniform: sd (b - a)/sqrt(12); 5 standard errors of the mean.
    assert all(5.0 <= r[0] <= 7.0 for r in runs) and abs(statistics.fmean(r[0] for r in runs) - 6.0) < 0.07
    assert all(10.0 <= r[1] <= 14.0 for r in runs) and abs(statistics.fmean(r[1] for r in runs) - 12.0) < 0.13
    assert sum(r[1] < 12.0 for r in runs) / len(runs) == pytest.approx(0.5, abs=5 * math.sqrt(0.25 / 2000))


def test_a_normal_range_truncates_the_distribution(corpus):
    # N(20, sd 2) in [18, 30]: a truncated normal (density renormalised inside the range), so
    # no draw sits on the bound (clipping would put P(X < 18) = 16 % of them at 18).
    got = imported(corpus, stochastic(2000, 1, {
        "EgoS": '<NormalDistribution expectedValue="20" variance="4"><Range lowerLimit="18" upperLimit="30"/>'
                "</NormalDistribution>"}))
    assert got.text is not None, errors(got)
    assert "param EgoS = 20 m in [18 m, 30 m] dist normal mean 20 m sd 2 m" in got.text
    assert not any(d.code == "W0802" and "EgoS" in d.message for d in got.diagnostics)
    ego = [r[0] for r in runs_of(got, "EgoS")]
    assert all(18.0 <= v <= 30.0 for v in ego) and sum(v == 18.0 for v in ego) == 0
    # The mean of N(20, 2) truncated below at 18 (alpha = -1): 20 + 2 phi(-1) / (1 - Phi(-1)) = 20.575.
    assert statistics.fmean(ego) == pytest.approx(20.575, abs=5 * 1.7 / math.sqrt(2000))


def test_log_normal_uneven_histogram_and_weighted_set_draw_as_the_standard_says(corpus):
    got = imported(corpus, stochastic(3000, 5, {
        "EgoS": '<LogNormalDistribution expectedValue="20" variance="16"/>',
        "TargetS": '<Histogram><Bin weight="1"><Range lowerLimit="10" upperLimit="12"/></Bin>'
                   '<Bin weight="3"><Range lowerLimit="12" upperLimit="14"/></Bin></Histogram>',
        "EgoSpeed": '<ProbabilityDistributionSet><Element value="100" weight="0.3333"/>'
                    '<Element value="120" weight="0.6667"/></ProbabilityDistributionSet>'}))
    assert got.text is not None, errors(got)
    assert "dist lognormal mean 20 m sd 4 m" in got.text
    assert "dist histogram bins [10 m, 12 m, 14 m] weights [1, 3]" in got.text
    assert "weights [0.3333, 0.6667]" in got.text
    runs = runs_of(got, "EgoS", "TargetS", "EgoSpeed")
    ego = [r[0] for r in runs]
    # The log-normal's own mean 20 and sd 4 (variance 16); standard errors 0.07 and ~0.08.
    assert min(ego) > 0 and abs(statistics.fmean(ego) - 20.0) < 0.4 and abs(statistics.stdev(ego) - 4.0) < 0.5
    low_bin = sum(r[1] < 12.0 for r in runs) / len(runs)
    assert low_bin == pytest.approx(0.25, abs=5 * math.sqrt(0.25 * 0.75 / 3000))
    assert len({r[2] for r in runs}) == 2
    share = sum(r[2] == min(r[2] for r in runs) for r in runs) / len(runs)
    assert share == pytest.approx(0.3333, abs=5 * math.sqrt(0.2222 / 3000))


def test_a_poisson_distribution_of_a_length_is_refused(corpus):
    # Poisson counts (`dist poisson` is dimensionless): EgoS is a station in metres.
    refused = imported(corpus, stochastic(10, 1, {"EgoS": '<PoissonDistribution expectedValue="3"/>'}))
    assert refused.text is None and any("counts" in e for e in errors(refused)), errors(refused)


@pytest.mark.parametrize("dist, missing", [
    ('<UserDefinedDistribution type="mine">x</UserDefinedDistribution>', "user-defined"),
    ('<LogNormalDistribution expectedValue="-1" variance="1"/>', "must be positive"),
    ('<Histogram><Bin weight="1"><Range lowerLimit="10" upperLimit="13"/></Bin>'
     '<Bin weight="3"><Range lowerLimit="12" upperLimit="14"/></Bin></Histogram>', "overlap"),
])
def test_what_the_language_cannot_draw_is_refused_by_name(corpus, dist, missing):
    got = imported(corpus, stochastic(10, 1, {"EgoS": dist}))
    assert got.text is None
    found = [d for d in got.diagnostics if d.is_error]
    assert any(missing in d.message for d in found), errors(got)
    assert all(d.span.file.endswith("variation.xosc") and d.span.line > 4 for d in found)


@pytest.mark.parametrize("name, said", [
    ("LaneChange1Time", "does not read parameter 'LaneChange1Time' as a value"),  # a condition's time, as a number
    ("HostVehicle", "is a string: only numbers are swept"),
    ("Nobody", "declares no parameter 'Nobody'"),
])
def test_parameters_it_cannot_vary_are_refused(corpus, name, said):
    got = imported(corpus, "<Deterministic>\n" + single(
        name, '<DistributionSet><Element value="1"/><Element value="2"/></DistributionSet>') + "</Deterministic>\n")
    assert got.text is None and any(said in e for e in errors(got)), errors(got)


def test_constraint_groups_become_assumptions_and_skipped_cells_are_counted(corpus):
    # EgoS in 10, 15, 20, 25, 30 with groups (>= 12 and <= 27) or (== 30): 10 is skipped.
    acc = corpus / "xosc" / "acc-test.xosc"
    acc.write_text(acc.read_text().replace(
        '<ParameterDeclaration name="EgoS" parameterType="double" value="20"/>',
        '<ParameterDeclaration name="EgoS" parameterType="double" value="20"><ConstraintGroup>'
        '<ValueConstraint rule="greaterOrEqual" value="12"/><ValueConstraint rule="lessOrEqual" value="27"/>'
        '</ConstraintGroup><ConstraintGroup><ValueConstraint rule="equalTo" value="30"/></ConstraintGroup>'
        "</ParameterDeclaration>"))
    got = imported(corpus, "<Deterministic>\n" + single(
        "EgoS", '<DistributionRange stepWidth="5"><Range lowerLimit="10" upperLimit="30"/></DistributionRange>')
        + "</Deterministic>\n")
    assert got.text is not None, errors(got)
    assert re.search(r"assume EgoS_valid: .*EgoS >= 12 m.*or.*EgoS == 30 m", got.text), got.text
    stream_runs = sorted(r[0] for r in runs_of(got, "EgoS"))
    assert stream_runs == [15.0, 20.0, 25.0, 30.0]
    assert any(d.code == "W0802" and "1 of 5 combinations break" in d.message for d in got.diagnostics)
    assert expand(got.plan).rejected == {"EgoS_valid": 1}


def test_too_many_runs_are_refused_before_anything_is_built(corpus):
    # 1e12 range values: refused from the count alone (a list would not fit in memory).
    start = time.perf_counter()
    got = imported(corpus, "<Deterministic>\n" + single(
        "EgoS", '<DistributionRange stepWidth="1e-9"><Range lowerLimit="0" upperLimit="1000"/></DistributionRange>')
        + "</Deterministic>\n")
    assert time.perf_counter() - start < 5
    assert got.text is None and any(e.startswith("E0701") and "1,000,000 runs" in e for e in errors(got))
    got = imported(corpus, stochastic(2_000_000, 1, {
        "EgoS": '<UniformDistribution><Range lowerLimit="5" upperLimit="7"/></UniformDistribution>'}))
    assert got.text is None and any("numberOfTestRuns=2,000,000" in e for e in errors(got)), errors(got)


def test_addtc_import_writes_the_addt_and_it_compiles(corpus, tmp_path, capsys):
    src = write(corpus, "<Deterministic>\n" + single(
        "TargetS", '<DistributionSet><Element value="80"/><Element value="120"/></DistributionSet>')
        + "</Deterministic>\n")
    out = tmp_path / "out" / "variation.addt"
    assert main(["import", str(src), "--root", str(corpus), "-o", str(out)]) == 0
    assert "grid TargetS in [80 m, 120 m]" in out.read_text()
    assert main(["check", str(out)]) == 0
