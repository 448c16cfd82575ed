"""Falsification against a synthetic judge: the space, the sampler, the report."""

from __future__ import annotations

import math

import numpy as np
import pytest
from tests.unit.search.search_testkit import KITCHEN_SINK, judged, kitchen_sink_plan

from addt_dsl.compiler import compile_source
from addt_dsl.plan import RunSpec
from addt_dsl.search.cache import RunCache
from addt_dsl.search.falsify import Falsifier, origin_of
from addt_dsl.search.samplers.cem import CrossEntropySampler
from addt_dsl.search.samplers.uniform import UniformSampler
from addt_dsl.search.space import SearchSpace
from addt_dsl.runtime.result import Failure, RunResult
from addt_dsl.sweep import violated_assumptions


def corner_judge(spec: RunSpec) -> RunResult:
    """Fails when v_lead is high and gap is low (a corner of the box): robustness is the
    distance to that corner, so it guides a search there."""
    v = (spec.params.get("v_lead", 15.0) - 5.0) / 20.0
    g = (spec.params.get("gap", 30.0) - 10.0) / 50.0
    rho = math.hypot(1.0 - v, g) - 0.2
    failures = (Failure("no_collision", "clearance(ego) > 0 m [with lead]", 1.0, rho),) if rho < 0 else ()
    return judged(spec, {"no_collision": rho}, failures)


def _falsifier(sampler="cem", seed=0, judge=corner_judge):
    return Falsifier(kitchen_sink_plan(), seed=seed, batch=8, sampler=sampler, cache=RunCache(evaluator=judge))


def test_space_axes():
    space = SearchSpace(kitchen_sink_plan())
    names = [a.name for a in space.axes]
    # Parameters with a range or choices; `brake_at` has neither.
    assert {"param:v_lead", "param:gap", "param:yaw_err", "param:k"} <= set(names)
    assert "param:brake_at" not in names
    # Every fault can be present or not and move in time; instants stay instants.
    for i in range(5):
        assert f"fault{i}:present" in names and f"fault{i}:start" in names
    assert "fault1:length" not in names  # `at 2 s shift ...`
    # Constant magnitudes are axes; settings written with a parameter move with it.
    assert "fault0:rate" in names and "fault0:burst" in names
    assert "fault1:yaw" not in names and "fault1:x" in names
    assert "fault2:count" not in names  # `count k`
    assert "fault4:value" in names


def test_severe_ends_of_the_fault_axes():
    space = SearchSpace(kitchen_sink_plan())
    severe = {a.name: a.severe for a in space.axes}
    assert all(v is None for k, v in severe.items() if k.startswith("param:"))
    # A window's worst is the whole run: from the start, as long as it can be.
    assert severe["fault4:present"] == 1.0 and severe["fault4:start"] == 0.0 and severe["fault4:length"] == 1.0
    assert severe["fault1:start"] is None  # an instant has no worst time
    # The setting's end farthest from neutral: up for a drop rate, down for a negative stuck value.
    assert severe["fault0:rate"] == 1.0 and severe["fault4:value"] == 0.0 and severe["fault1:x"] == 0.0
    u = np.full(space.dims, 0.5)
    for name, v in severe.items():
        if v is not None:
            u[space.index[name]] = v
    faults = {f.kind: f for f in space.spec(u, 1, "severe").faults}
    assert faults["stuck"].settings["value"] == pytest.approx(-4.0) and faults["stuck"].start_s == 0.0
    assert faults["stuck"].end_s == pytest.approx(space.plan.duration_s)
    assert faults["drop"].settings["rate"] == pytest.approx(0.1)
    assert faults["shift"].settings["x"] == pytest.approx(-0.4)


def test_candidates_are_valid_pinned_runs():
    fal = _falsifier()
    points, specs = fal._candidates(40, 0)
    assert len(specs) == 40
    space = fal.space
    for u, spec in zip(points, specs):
        assert not violated_assumptions(kitchen_sink_plan(), {**space.nominal, **spec.params})
        assert spec.plan.run_seed == spec.seed and not spec.plan.sweep.grid
        present = sum(u[space.index[f"fault{i}:present"]] >= 0.5 for i in range(5))
        assert len(spec.faults) == present
        for f in spec.faults:
            assert 0.0 <= f.start_s <= spec.plan.duration_s
            assert f.end_s is None or f.start_s <= f.end_s <= spec.plan.duration_s + 1e-9
            if f.kind == "stuck":
                assert -4.0 <= f.settings["value"] <= 0.0  # neutral 0 to twice the declared -2
            if f.kind == "drop":
                assert 0.0 <= f.settings["rate"] <= 0.1 and 1.0 <= f.settings["burst"] <= 6.0


def test_same_seed_same_search():
    def search(seed):
        runs = []

        def judge(spec):
            runs.append(spec.key())
            return corner_judge(spec)
        report = _falsifier(seed=seed, judge=judge).run(budget_runs=48, shrink_simulations=0).to_json()
        report.pop("seconds")
        return report, runs

    (a, runs_a), (b, runs_b), (_, runs_c) = search(3), search(3), search(4)
    assert a["failures"] and a["first_failure_run"] is not None  # both found failures, so the comparison says something
    assert len(runs_a) == 48 and runs_a == runs_b and a == b  # the same runs in the same order, the same report
    assert runs_c != runs_a  # and another seed searches differently


def test_guided_search_reaches_a_rare_corner_sooner_than_random():
    def first(sampler):
        runs = [_falsifier(sampler, seed).run(budget_runs=200, shrink_simulations=0,
                                              stop_at_first=True).first_failure_run or 201 for seed in range(6)]
        return float(np.mean(runs))

    cem, rnd = first("cem"), first("random")
    assert cem < rnd, (cem, rnd)


def test_cem_concentrates_on_the_elite():
    rng = np.random.default_rng(0)
    space = SearchSpace(kitchen_sink_plan())
    cem = CrossEntropySampler(space.axes, rng)
    points = UniformSampler(space.dims, rng).sample(64)
    scores = np.abs(points[:, 0] - 0.9)  # the best points have axis 0 near 0.9
    cem.update(points, scores)
    assert abs(cem.mu[0] - 0.9) < 0.2 and cem.sigma[0] < 0.3
    assert cem.fitted


def test_failures_are_reported_with_their_shrunk_origin():
    report = _falsifier().run(budget_runs=96, shrink_simulations=80)
    assert report.failures, report.to_json()
    f = report.failures[0]
    assert f.oracle == "no_collision" and f.shrunk is not None
    # The judge only cares about v_lead and gap: no fault is needed, gap stays off nominal.
    assert not f.shrunk.best.faults
    assert "gap = " in f.origin and "v_lead = " in f.origin
    assert report.first_failure_run == f.first_run


def test_origin_of_a_nominal_run():
    plan = kitchen_sink_plan()
    spec = RunSpec(plan=plan, params=plan.nominal_params(), seed=1, faults=[])
    assert origin_of(spec, plan.nominal_params()) == "nominal scenario (no fault, nominal parameters)"


@pytest.mark.parametrize("sampler", ["cem", "random"])
def test_no_failure_no_report(sampler):
    def safe(spec):
        return judged(spec, {"no_collision": 1.0}, ())

    report = _falsifier(sampler, judge=safe).run(budget_runs=20, shrink_simulations=10)
    assert report.failures == [] and report.first_failure_run is None and report.runs == 20


def test_falsify_ignores_the_files_sweep_cost(tmp_path, capsys):
    # A sweep too large for `addtc FILE` (E0701) can still be searched: falsify runs its
    # own budget, never the file's sweep.
    from addt_dsl.cli import main

    path = tmp_path / "big.addt"
    path.write_text("scenario big {\n  duration 1 s\n  road r {\n    line length 300 m\n"
                    "    lanes right 1 width 3.5 m\n  }\n  param v = 10 m/s in [5 m/s, 15 m/s]\n"
                    "  ego car on r lane -1 at 20 m speed v\n  expect {\n    no collision\n  }\n"
                    "  sweep {\n    random 1000000 seed 1\n    repeat 100\n  }\n}\n")
    assert main(["check", str(path)]) == 2 and "E0701" in capsys.readouterr().err
    assert main(["falsify", str(path), "--budget-runs", "2", "--no-write"]) == 0
    assert "2 runs" in capsys.readouterr().out


def edge_judge(spec: RunSpec) -> RunResult:
    """Fails only for gap in (12 m, 12.5 m): the kitchen sink assumes gap > 12 m, so the
    failure region borders the assumption and robustness keeps falling across it."""
    rho = (spec.params.get("gap", 30.0) - 12.5) / 50.0
    failures = (Failure("no_collision", "clearance(ego) > 0 m [with lead]", 1.0, rho),) if rho < 0 else ()
    return judged(spec, {"no_collision": rho}, failures)


@pytest.mark.parametrize("sampler", ["bo", "bandit"])
def test_the_model_keeps_searching_where_a_failure_borders_an_assumption(sampler):
    # The model extrapolated the falling robustness across `gap > 12 m`; its best points
    # were rejected unrun at every ask. `bo` ended silently after ~17 of its 120 runs
    # without a failure (5 of these 6 seeds); the bandit fell back to uniform points in the
    # arm and found nothing in 120 runs for 3 of them.
    for seed in range(6):
        report = _falsifier(sampler, seed, edge_judge).run(budget_runs=120, shrink_simulations=0, stop_at_first=True)
        assert report.first_failure_run is not None and not report.ended_early, (seed, report.to_json())


def test_a_search_the_assumptions_starve_says_why_it_ended():
    plan = compile_source(KITCHEN_SINK.replace("assume gap > 12 m", "assume gap > 59 m"),
                          path="starved.addt").plan
    report = Falsifier(plan, seed=0, batch=8, sampler="random",
                       cache=RunCache(evaluator=corner_judge)).run(budget_runs=50, shrink_simulations=0)
    assert report.runs == 0 and "assumptions rejected all 400 points" in report.ended_early
    assert report.to_json()["ended_early"] == report.ended_early


def test_falsify_shrinks_the_same_in_batches():
    """`--shrink-batch`: each distinct failure's shrink runs its candidates in batches, the
    same shrunk runs and report as one at a time (budget not spent)."""
    reports = []
    for shrink_batch in (1, 6):
        fal = Falsifier(kitchen_sink_plan(), seed=0, batch=8, sampler="cem", cache=RunCache(evaluator=corner_judge),
                        shrink_batch=shrink_batch)
        report = fal.run(budget_runs=96, shrink_simulations=200)
        shrunk = [f.shrunk for f in report.failures]
        assert shrunk and all(s is not None and not s.budget_exhausted for s in shrunk)
        assert all(s.batch == shrink_batch and (s.ran_ahead > 0) == (shrink_batch > 1) for s in shrunk)
        summary = report.to_json()
        del summary["seconds"]
        reports.append((summary, [(s.best.key(), s.simulations, s.cache_hits) for s in shrunk]))
    assert reports[1] == reports[0]
