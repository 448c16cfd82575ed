"""The shrinker on fault windows a condition opens (`when C for W`): it drops them or
shortens their length, never moves their start off the condition, and what it ends on
prints and compiles back as the same run."""

from __future__ import annotations

from tests.unit.search.search_testkit import judged

from addt_dsl.compiler import compile_source
from addt_dsl.printer import compile_pinned, pin_spec, print_spec
from addt_dsl.runtime.result import Failure
from addt_dsl.search import RunCache, Shrinker
from addt_dsl.sweep import expand

SOURCE = """scenario opened {
  duration 20 s
  step 50 ms
  road street {
    line length 600 m
  }
  ego car on street lane -1 at 10 m speed 10 m/s {
    stack bev cruise_speed 15 m/s
  }
  agent lead car on street lane -1 at 40 m speed 5 m/s {
    slow: at 2 s then behavior brake decel 2 m/s^2 to_speed 1 m/s
  }
  faults {
    when started(lead.slow) for 12 s drop lidar rate 20 %
    when rising gap(ego, lead) < 15 m delay lidar by 30 ms
  }
  expect {
    no collision
  }
}
"""


class FailsWithFirstFault:
    """Fails `no_collision` at `t_v` while the drop is in the run and its window reaches
    3 s past its opening (a later start would still reach it: only the length matters)."""

    def __init__(self, t_v: float):
        self.t_v = t_v

    def __call__(self, spec):
        if any(f.kind == "drop" and (f.end_s is None or f.end_s >= 3.0) for f in spec.faults):
            return judged(spec, {}, (Failure("no_collision", "clearance(ego) > 0 m", self.t_v, -0.5),))
        return judged(spec, {"no_collision": 0.5})


def _spec():
    result = compile_source(SOURCE, path="opened.addt")
    assert result.ok, result.diagnostics
    return result.plan, expand(result.plan).specs[0]


def _shrink(t_v: float):
    plan, spec = _spec()
    return Shrinker(spec, nominal_plan=plan, cache=RunCache(evaluator=FailsWithFirstFault(t_v)),
                    max_simulations=80).run()


def test_the_culprit_window_stays_opened_by_its_condition_and_shrinks_its_length():
    shrunk = _shrink(6.0)
    (f,) = shrunk.best.faults  # the delay did not matter
    assert f.kind == "drop" and f.opens is not None
    assert f.start_s == 0.0 and f.end_s is not None and 3.0 <= f.end_s < 3.1
    assert f.end_s <= shrunk.best.plan.duration_s
    assert any("did not matter" in c and "delay" in c and "when its condition holds" in c for c in shrunk.changes)
    # No candidate moved the start off the condition (it would not print: refused, wasted).
    assert [p.rejected for p in shrunk.stats if p.name == "shorten_windows"] == [0]


def test_the_shrunk_run_prints_and_compiles_back_to_the_same_faults():
    shrunk = _shrink(1.0)
    replay = compile_pinned(print_spec(shrunk.best), path="opened.addt")
    assert [f.model_dump(exclude={"index"}) for f in replay.faults] == \
        [f.model_dump(exclude={"index"}) for f in pin_spec(shrunk.best).faults]
    assert all(f.opens is not None for f in replay.faults)
