"""The bandit sampler (`--sampler bandit`) on synthetic scores (no simulation): with six
declared faults of which one can fail, it spends its runs on that fault's arm and reaches the
failure sooner than `bo`; its first runs are each fault's worst case; points belong to the arm
their present axes say; same seed, same points; and it runs inside the falsifier."""

from __future__ import annotations

import numpy as np
from tests.unit.search.search_testkit import judged, kitchen_sink_plan
from tests.unit.search.test_bo_sampler import evaluations_to_failure

from addt_dsl.runtime.result import Failure
from addt_dsl.search.cache import RunCache
from addt_dsl.search.falsify import Falsifier
from addt_dsl.search.samplers.bandit import BANDIT_MIN_MODEL, BanditSampler
from addt_dsl.search.samplers.bo import BayesianSampler
from addt_dsl.search.space import Axis

FAULTS = 6
CULPRIT = 3
AXES = [Axis(f"param:p{i}", "unit") for i in range(3)]
for _k in range(FAULTS):
    AXES += [Axis(f"fault{_k}:present", "bool", severe=1.0), Axis(f"fault{_k}:start", "unit", severe=0.0),
             Axis(f"fault{_k}:length", "unit", severe=1.0), Axis(f"fault{_k}:value", "unit", severe=1.0)]
PRESENT = [3 + 4 * k for k in range(FAULTS)]


def one_culprit_score(u: np.ndarray) -> np.ndarray:
    """Fails only with fault 3 present, near p0 = p1 = 1, an early start and a high value
    (0.4 % of the cube); the other faults change nothing, and without fault 3 the score stays
    above 0.5 (set by p0 and p1)."""
    u = np.atleast_2d(u)
    base = PRESENT[CULPRIT]
    d = np.sqrt((1 - u[:, 0]) ** 2 + (1 - u[:, 1]) ** 2 + u[:, base + 1] ** 2 + (1 - u[:, base + 3]) ** 2)
    return np.where(u[:, base] >= 0.5, d - 0.4, 0.5 + np.hypot(1 - u[:, 0], 1 - u[:, 1]))


def run(sampler, budget: int) -> tuple[np.ndarray, np.ndarray]:
    """`budget` evaluations (no stop at a failure), in the batches the sampler asks for."""
    points = np.empty((0, len(AXES)))
    while len(points) < budget:
        points = np.vstack([points, sampler.sample(min(sampler.batch_size(8, len(points)), budget - len(points)))])
        sampler.update(points, one_culprit_score(points))
    return points, one_culprit_score(points)


def test_the_culprits_arm_gets_the_runs():
    rate = float(np.mean(one_culprit_score(np.random.default_rng(0).random((100_000, len(AXES)))) < 0))
    assert 0.002 < rate < 0.007
    for seed in range(2):
        sampler = BanditSampler(AXES, np.random.default_rng(seed), jobs=2)
        points, _ = run(sampler, 60)
        arms = sampler.classify(points)
        assert set(arms) <= set(range(FAULTS + 1))  # one fault or none: never several at once
        pulls = np.bincount(arms, minlength=FAULTS + 1)
        # Measured (seeds 0-3): 41-50 of 60 on the culprit's arm, at most 6 on any other.
        assert pulls[CULPRIT] >= 30 and pulls[CULPRIT] > 4 * np.delete(pulls, CULPRIT).max(), pulls


def test_bandit_reaches_a_one_fault_failure_sooner_than_bo():
    bandit = [evaluations_to_failure(BanditSampler(AXES, np.random.default_rng(s), jobs=2), one_culprit_score, 100)
              for s in range(4)]
    bo = [evaluations_to_failure(BayesianSampler(AXES, np.random.default_rng(s), jobs=2), one_culprit_score, 100)
          for s in range(4)]
    # Measured over seeds 0-7: bandit 4-23 (median 11), bo 4-25 (median 23): bo's start alone
    # (six worst cases and a hypercube of 13) is 19 evaluations.
    assert np.median(bandit) < 0.75 * np.median(bo), (bandit, bo)


def test_first_runs_are_each_faults_worst_case_then_no_fault():
    sampler = BanditSampler(AXES, np.random.default_rng(1), jobs=2)
    n = sampler.batch_size(8, 0)
    assert n == FAULTS + 1
    first = sampler.sample(n)
    for k in range(FAULTS):
        on = first[k, PRESENT] >= 0.5
        assert on.sum() == 1 and on[k]
        # from the start, for the whole run, at the top of its setting
        assert np.array_equal(first[k, PRESENT[k] + 1:PRESENT[k] + 4], [0.0, 1.0, 1.0])
    assert not (first[FAULTS, PRESENT] >= 0.5).any()
    # Until its model, an arm's runs stay at the worst case; the parameters move.
    sampler.update(first, one_culprit_score(first))
    later = sampler.sample(BANDIT_MIN_MODEL * (FAULTS + 1))
    arms = sampler.classify(later)
    early = later[arms == CULPRIT][: BANDIT_MIN_MODEL - 1]
    assert np.all(early[:, PRESENT[CULPRIT] + 1:PRESENT[CULPRIT] + 4] == [0.0, 1.0, 1.0])
    assert len(np.unique(early[:, 0])) == len(early)


def test_points_belong_to_the_arm_their_present_axes_say():
    sampler = BanditSampler(AXES, np.random.default_rng(0))
    u = np.full((4, len(AXES)), 0.2)
    u[1, PRESENT[2]] = 0.7
    u[2, PRESENT[5]] = 0.5
    u[3, [PRESENT[0], PRESENT[4]]] = 0.9
    assert list(sampler.classify(u)) == [FAULTS, 2, 5, -1]  # none, fault 2, fault 5, several (no arm)


def test_same_seed_same_points():
    a, _ = run(BanditSampler(AXES, np.random.default_rng(7), jobs=2), 30)
    b, _ = run(BanditSampler(AXES, np.random.default_rng(7), jobs=2), 30)
    c, _ = run(BanditSampler(AXES, np.random.default_rng(8), jobs=2), 30)
    assert np.array_equal(a, b) and not np.array_equal(a, c)


def test_bandit_in_the_falsifier_finds_a_parameter_corner():
    def corner(spec):  # fails near the top of v_lead and the bottom of gap, whatever the faults
        v = (spec.params.get("v_lead", 15.0) - 5.0) / 20.0
        g = (spec.params.get("gap", 30.0) - 10.0) / 50.0
        rho = float(np.hypot(1.0 - v, g) - 0.25)
        failures = (Failure("no_collision", "clearance(ego) > 0 m [with lead]", 1.0, rho),) if rho < 0 else ()
        return judged(spec, {"no_collision": rho}, failures)

    def search():
        return Falsifier(kitchen_sink_plan(), seed=2, sampler="bandit",
                         cache=RunCache(evaluator=corner)).run(budget_runs=60, shrink_simulations=0)

    report = search()
    assert report.sampler == "bandit" and report.first_failure_run is not None, report.to_json()
    assert search().to_json()["failures"] == report.to_json()["failures"]
