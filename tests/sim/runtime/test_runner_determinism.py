"""Same results, in any order, for any worker count and executor."""


import pytest

from tests.sim.runner_simkit import limit_scenario

from addt_dsl.compiler import compile_file
from addt_dsl.runtime.executor import InlineExecutor, LocalExecutor, run_sweep
from addt_dsl.runtime.store import ResultStore
from addt_dsl.sweep import SweepStream

pytestmark = pytest.mark.slow


def _results(store: ResultStore) -> dict:
    return {(r.key, r.run_id): (r.digest, r.status, [(v.name, v.robustness, v.passed, v.first_violation_s)
                                                      for v in r.verdicts], r.stats)
            for r in store.records()}


def _sweep(plan, path, executor) -> dict:
    with ResultStore(path, plan) as store:
        run_sweep(SweepStream(plan), store, executor)
        assert len(store) == len(SweepStream(plan))
        return _results(store), [r.worker for r in store.records(order="finished_at")]


@pytest.fixture(scope="module")
def plan(tmp_path_factory):
    return compile_file(limit_scenario(tmp_path_factory.mktemp("det"), repeat=2, duration="4 s")).plan


@pytest.fixture(scope="module")
def one_worker(plan, tmp_path_factory):
    return _sweep(plan, tmp_path_factory.mktemp("w1") / "r.sqlite", LocalExecutor(1))[0]


def test_one_and_two_workers_give_the_same_runs(plan, one_worker, tmp_path):
    two, workers = _sweep(plan, tmp_path / "r.sqlite", LocalExecutor(2))
    assert two == one_worker
    assert len(set(workers)) == 2  # both workers did runs
    digests = {v[0] for v in one_worker.values()}
    assert len(digests) == len(one_worker)  # repeats really differ (seeded per run)
    verdicts = {rid: v[2][0][2] for (_, rid), v in one_worker.items()}
    assert {rid[:4]: ok for rid, ok in verdicts.items()} == {"c000": False, "c001": False, "c002": True,
                                                             "c003": True}


def test_batched_workers_give_the_same_runs(plan, one_worker, tmp_path):
    """Workers stepping batches of 3 (runs of different cells side by side): the same records."""
    assert _sweep(plan, tmp_path / "r.sqlite", LocalExecutor(2, batch=3))[0] == one_worker


def test_in_process_execution_matches_workers(plan, one_worker, tmp_path):
    assert _sweep(plan, tmp_path / "r.sqlite", InlineExecutor())[0] == one_worker


def test_ray_executor_matches_local_workers(plan, one_worker, tmp_path):
    ray = pytest.importorskip("ray")
    from addt_dsl.runtime.ray_executor import RayExecutor

    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        results, workers = _sweep(plan, tmp_path / "r.sqlite", RayExecutor(timeout_s=120, batch=3))
    finally:
        ray.shutdown()
    assert results == one_worker
    assert all(w.startswith("ray-pid") for w in workers)
