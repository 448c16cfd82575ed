"""The shrinker never ends on a run that does not compile as a scenario.

Generated scenarios tie values to each other the way users do (`reach goal within T`,
oracle windows, fault times and windows, a step `at T`, a relative placement `at x + gap`);
a synthetic judge fails every candidate early, so every pass (above all the cut of the
run's duration after the violation) pushes against those ties. Each result is printed
and compiled again, as `addtc shrink`, `addtc falsify` and the pytest plugin write it.
"""

from __future__ import annotations

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from tests.unit.search.search_testkit import judged

from addt_dsl.compiler import compile_source
from addt_dsl.printer import compile_pinned, print_spec, side_files
from addt_dsl.runtime.result import Failure
from addt_dsl.search import RunCache, Shrinker
from addt_dsl.search.artifacts import NotCompilable, write_counterexample
from addt_dsl.sweep import expand

TEMPLATE = """scenario tied {{
  duration {dur} s
  step 50 ms
  road street {{
    line length 600 m
  }}
  param gap = {gap} m in [10 m, 60 m]
  param t_f = {t_f} s in [0 s, {dur} s]
  ego car on street lane -1 at {s0} m speed 10 m/s goal {goal} m {{
    stack bev cruise_speed 15 m/s
  }}
  agent lead car on street lane -1 at {s0} m + gap speed 5 m/s {{
    slow: at {t_step} s then behavior brake decel 2 m/s^2 to_speed 1 m/s
  }}
  faults {{
    at t_f stuck control.accel value 2
    during [{w_lo} s, {w_hi} s] drop lidar rate 20 %
  }}
  expect {{
    no collision
    reach goal within {within} s
    always during [{o_lo} s, {o_hi} s] speed(ego) < 40 m/s
    warn late: eventually within {ev} s speed(ego) > 0 m/s
  }}
  sweep {{
    grid gap in [{gap}, 55] m
  }}
}}
"""


@st.composite
def tied_sources(draw) -> str:
    dur = draw(st.integers(4, 20))
    t = st.floats(0.0, float(dur), allow_nan=False).map(lambda v: round(v, 2))
    w_lo = draw(t)
    o_lo = draw(t)
    return TEMPLATE.format(
        dur=dur, gap=draw(st.integers(10, 50)), t_f=draw(t), s0=draw(st.integers(5, 100)),
        goal=draw(st.integers(150, 400)), t_step=draw(t), w_lo=w_lo,
        w_hi=draw(st.floats(w_lo, float(dur)).map(lambda v: round(v, 2))), within=draw(t),
        o_lo=o_lo, o_hi=draw(st.floats(o_lo, float(dur)).map(lambda v: round(v, 2))), ev=draw(t))


class EarlyFailure:
    """Every run fails `no_collision` at `t_v` (the first 10 % of the run): a shrinker
    that cuts the run right after it goes below every time tied to the duration."""

    def __init__(self, t_v: float):
        self.t_v = t_v

    def __call__(self, spec):
        failure = Failure("no_collision", "clearance(ego) > 0 m [with lead]", self.t_v, -0.5)
        return judged(spec, {"no_collision": -0.5}, (failure,))


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(source=tied_sources(), frac=st.floats(0.0, 0.1))
def test_every_shrunk_run_compiles(source, frac, tmp_path_factory):
    result = compile_source(source, path="tied.addt")
    assert result.ok, result.diagnostics
    plan = result.plan
    spec = expand(plan).specs[-1]
    judge = EarlyFailure(round(frac * plan.duration_s, 2))
    shrunk = Shrinker(spec, nominal_plan=plan, cache=RunCache(evaluator=judge), max_simulations=60).run()
    out = tmp_path_factory.mktemp("shrunk")
    for name, body in side_files(shrunk.best.plan).items():
        (out / name).write_text(body)
    replay = compile_pinned(print_spec(shrunk.best), path=str(out / "tied.addt"), base_dir=out)
    assert replay.key() == shrunk.best.key() or replay.plan.duration_s == shrunk.best.plan.duration_s


def test_the_duration_is_cut_down_to_the_tightest_tie():
    """`reach goal within 9 s` in a 20 s run failing at 1 s: the run ends at 9 s, not at
    1.5 s (E0302 when written) and not at 20 s."""
    source = TEMPLATE.format(dur=20, gap=30, t_f=1, s0=10, goal=300, t_step=2, w_lo=0.5, w_hi=1, within=9,
                             o_lo=0, o_hi=3, ev=2)
    plan = compile_source(source, path="tied.addt").plan
    spec = expand(plan).specs[0]
    shrunk = Shrinker(spec, nominal_plan=plan, cache=RunCache(evaluator=EarlyFailure(1.0)), max_simulations=60).run()
    assert shrunk.best.plan.duration_s == 9.0
    assert shrunk.stats[0].rejected >= 1  # the cut to 1.5 s, refused without a simulation
    compile_pinned(print_spec(shrunk.best), path="tied.addt")


def test_a_counterexample_that_does_not_compile_is_never_written(tmp_path):
    """Defence in depth: `write_counterexample` compiles before it writes the `.addt`."""
    source = TEMPLATE.format(dur=20, gap=30, t_f=1, s0=10, goal=300, t_step=2, w_lo=0.5, w_hi=1, within=9,
                             o_lo=0, o_hi=3, ev=2)
    plan = compile_source(source, path="tied.addt").plan
    spec = expand(plan).specs[0]
    shrunk = Shrinker(spec, nominal_plan=plan, cache=RunCache(evaluator=EarlyFailure(1.0)), max_simulations=5).run()
    broken = shrunk.best.plan.model_copy(update={"duration_s": 2.0})
    shrunk.best = shrunk.best.model_copy(update={"plan": broken})
    try:
        write_counterexample(shrunk, tmp_path, "tied.addt", animate=False)
    except NotCompilable as exc:
        assert "E0302" in str(exc)
    else:
        raise AssertionError("a run that does not compile was written")
    assert not list(tmp_path.glob("*.addt"))
