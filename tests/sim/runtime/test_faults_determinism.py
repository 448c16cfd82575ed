"""Same RunSpec, same faults at the same instants; each fault draws from its own seed."""

from __future__ import annotations

import pytest

from addt_dsl.runtime.execute import execute
from addt_dsl.runtime.executor import run_local
from tests.sim.runtime.test_faults_outcomes import specs

pytestmark = pytest.mark.slow

MANY = """\
    drop lidar rate 10 % burst 2
    during [0.5 s, 3 s] delay lidar by 20 ms jitter 100 ms
    noise lidar range 5 cm dropout 20 %
    at 1 s shift lidar yaw 1 deg
    during [0.5 s, 3 s] bitflip control count 5 field mantissa
    during [1 s, 2 s] random_value planner.speed low 10 high 20
    during [1 s, 2 s] spike tracker by 30 ms"""


def _events(result):
    return [(e.time_s, sorted(e.detail.items())) for e in result.trace.events if e.kind == "fault"]


def test_same_runspec_same_fault_events_and_trace():
    s = specs(MANY, duration_s=3.0)[0]
    a, b = execute(s), execute(s)
    assert a.digest == b.digest
    assert _events(a) == _events(b) and len(_events(a)) > 50
    kinds = {d["kind"] for _, d in map(lambda e: (e[0], dict(e[1])), _events(a))}
    assert kinds == {"drop", "delay", "noise", "shift", "bitflip", "random_value", "spike"}


def test_worker_count_does_not_change_fault_runs():
    many = specs(MANY, duration_s=3.0, extra="  param k = 0 in [0, 3]", sweep="  sweep {\n    repeat 3\n  }")
    one, two = run_local(many, jobs=1), run_local(many, jobs=2)
    assert [(r.run_id, r.digest, r.fault_events) for r in one] == [(r.run_id, r.digest, r.fault_events) for r in two]
    assert len({r.digest for r in one}) == 3  # repeats have their own seeds


def test_a_fault_s_draws_do_not_depend_on_the_other_faults():
    alone = specs("    drop lidar rate 30 % seed 77", duration_s=3.0)[0]
    with_more = specs("    drop lidar rate 30 % seed 77\n    noise lidar dropout 10 %", duration_s=3.0)[0]
    drops = lambda r: [e.time_s for e in r.trace.events if e.kind == "fault" and e.detail["kind"] == "drop"]  # noqa: E731
    assert drops(execute(alone)) == drops(execute(with_more)) != []
