"""Shared scenarios and Hypothesis strategies for the printer and search tests."""

from __future__ import annotations

import math
from functools import lru_cache
from pathlib import Path

from hypothesis import strategies as st

from addt_dsl import expr as E
from addt_dsl import units
from addt_dsl.compiler import compile_file, compile_source
from addt_dsl.plan import ConcreteFault, RunSpec, ScenarioPlan
from addt_dsl.registry import FAULTS, SENSORS, SIGNALS, STACKS
from addt_dsl.runtime.result import Failure, RunResult, Verdict
from addt_dsl.sweep import violated_assumptions

ROOT = Path(__file__).resolve().parents[3]
EXAMPLES = sorted((ROOT / "examples").glob("*.addt"))

# Every construct of the current grammar, in one scenario (kept as a string so that the
# pytest plugin never collects it as a test file).
KITCHEN_SINK = r'''
scenario kitchen_sink {
  description "All constructs: \"quotes\", back\\slash"
  duration 12 s
  step 20 ms
  seed 3

  road main {
    line length 100 m
    spiral length 50 m from 0 /m to 0.01 /m
    arc length 80 m curvature 0.01 /m
    param_poly3 length 40 m bu 1 cv 0.001
    lanes right 2 left 1 width 3.25 m offset 0.5 m
  }

  param v_lead = 15 m/s in [5 m/s, 25 m/s]
  param gap = 30 m in [10 m, 60 m] dist normal mean 30 m sd 10 m
  param yaw_err = 1 deg in [0 deg, 1 deg, 2 deg]
  param brake_at = 20 m
  param k = 2 in [1, 2, 3]
  assume gap > 12 m and v_lead < 24 m/s

  ego car on main lane -1 at 10 m speed 20 km/h goal 200 m mass 1800 kg mu 0.6 {
    stack bev cruise_speed 25 m/s time_gap 1.2 s perception ground_truth
    sensor lidar rate 20 Hz rays 180 range 60 m yaw 0.5 deg
  }
  agent lead truck on main lane -1 at 10 m + gap speed v_lead length 10 m height 3 m {
    behavior cruise speed v_lead accel 1 m/s^2
    brake_hard: when distance(ego, lead) < brake_at then behavior brake decel 5 m/s^2 to_speed 2 m/s
  }
  agent bike cyclist on main lane -2 at 60 m speed 4 m/s offset -0.5 m

  faults {
    drop lidar rate 5 % burst 3
    at 2 s shift lidar yaw yaw_err x -0.2 m
    during [1 s, 3 s] bitflip control.steer count k field exponent seed 11
    from 4 s spike planner by 50 ms
    during [5 s, 6 s] stuck control.accel value -2
  }

  expect {
    no collision
    no collision with lead
    warn comfort: always abs(accel(ego)) < 3 m/s^2
    always during [1 s, 5 s] ttc(ego, lead) > 2 s or not (speed(ego) > 1 m/s)
    hard safe: (speed(ego) < 30 m/s until within 3 s s(ego) > 20 m) implies eventually after 1 s gap(ego, lead) >= -(2 * 1 m)
    always latency(e2e) < 0.2 s and objects() >= 0
    always 2 * gap(ego, lead) / speed(lead) > -1 s
    warn slowed: always (ended(lead.brake_hard) implies started(lead.brake_hard) and speed(lead) < 2.5 m/s)
  }

  sweep {
    grid v_lead in [10, 15, 20] m/s
    halton 4 seed 9
    repeat 2
    seed 5
  }
}
'''  # noqa: E501 (the scenario's lines)


@lru_cache(maxsize=None)
def kitchen_sink_plan() -> ScenarioPlan:
    result = compile_source(KITCHEN_SINK, path="kitchen_sink.addt")
    assert result.ok, result.diagnostics
    return result.plan


@lru_cache(maxsize=None)
def example_plans() -> tuple[ScenarioPlan, ...]:
    plans = []
    for path in EXAMPLES:
        result = compile_file(path)
        assert result.ok, (path, result.diagnostics)
        plans.append(result.plan)
    return (*plans, kitchen_sink_plan())


# ---------------------------------------------------------------- values and formulas

finite = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False, allow_infinity=False)
nonneg = st.floats(min_value=0.0, max_value=1e3, allow_nan=False, allow_infinity=False)

ACTORS = ("ego", "lead")
NODES = ("perception", "tracker", "planner", "control", "e2e")


def _signals_of(dim) -> list[E.Signal]:
    out = []
    for cls in SIGNALS.classes():
        # step states are formulas; no lights or variables here (the plan declares none)
        if cls.dim != dim or cls.boolean or "light" in cls.args or "variable" in cls.args:
            continue
        pools = [ACTORS if kind == "actor" else NODES for kind in cls.args]
        if not pools:
            out.append(E.Signal(name=f"{cls.keyword}()"))
        elif len(pools) == 1:
            out += [E.Signal(name=f"{cls.keyword}({a})") for a in pools[0]]
        else:
            out += [E.Signal(name=f"{cls.keyword}({a},{b})") for a in pools[0] for b in pools[1] if a != b]
    return out


def values(dim, params: dict[str, units.Dim], depth: int = 3):
    """Value expressions of dimension `dim` that the compiler could have produced."""
    leaves = [finite.map(lambda v: E.Num(value=v))]
    sigs = _signals_of(dim)
    if sigs:
        leaves.append(st.sampled_from(sigs))
    names = sorted(n for n, d in params.items() if d == dim)
    if names:
        leaves.append(st.sampled_from(names).map(lambda n: E.Param(name=n)))
    leaf = st.one_of(*leaves)
    if depth == 0:
        return leaf
    sub = values(dim, params, depth - 1)
    plain = values(units.DIMENSIONLESS, params, depth - 1)
    nodes = [
        # Binary "-" is left out: the grammar cannot parse `a - b` yet (test_printer xfails on it).
        st.builds(lambda a, b: E.Binary(op="+", left=a, right=b), sub, sub),
        st.builds(lambda a, b: E.Binary(op="*", left=a, right=b), sub, plain),
        st.builds(lambda a, b: E.Binary(op="*", left=a, right=b), plain, sub),
        st.builds(lambda a, b: E.Binary(op="/", left=a, right=b), sub, plain),
        st.builds(lambda fn, args: E.Call(fn=fn, args=tuple(args)), st.sampled_from(["min", "max"]),
                  st.lists(sub, min_size=1, max_size=3)),
        sub.map(lambda a: E.Call(fn="abs", args=(a,))),
        sub.filter(lambda a: not isinstance(a, E.Num)).map(lambda a: E.Unary(op="neg", arg=a)),
    ]
    if dim == units.DIMENSIONLESS:
        nodes.append(sub.map(lambda a: E.Call(fn="sqrt", args=(a,))))
    return st.one_of(leaf, *nodes)


DIMS = (units.LENGTH, units.TIME, units.SPEED, units.ACCELERATION, units.ANGLE, units.DIMENSIONLESS,
        units.JERK, units.ANGULAR_RATE)


@st.composite
def windows(draw):
    # Windows must end inside the scenario (the compiler checks it): the kitchen sink lasts 12 s.
    lo = draw(st.one_of(st.just(0.0), st.floats(0.0, 6.0, allow_nan=False)))
    hi = draw(st.one_of(st.none(), st.floats(0.0, 6.0, allow_nan=False).map(lambda d: lo + d)))
    return lo, hi


def formulas(params: dict[str, units.Dim], depth: int = 3):
    comparison = st.sampled_from(DIMS).flatmap(
        lambda d: st.builds(lambda op, a, b: E.Binary(op=op, left=a, right=b),
                            st.sampled_from(list(E.COMPARE_OPS)), values(d, params, 2), values(d, params, 2)))
    leaf = st.one_of(comparison, st.sampled_from([E.Num(value=1.0), E.Num(value=-1.0)]))
    if depth == 0:
        return leaf
    sub = formulas(params, depth - 1)
    return st.one_of(
        leaf,
        sub.map(lambda a: E.Unary(op="not", arg=a)),
        st.builds(lambda op, a, b: E.Binary(op=op, left=a, right=b), st.sampled_from(["and", "or", "implies"]),
                  sub, sub),
        st.builds(lambda op, w, a: E.Temporal(op=op, lo_s=w[0], hi_s=w[1], arg=a),
                  st.sampled_from(["always", "eventually"]), windows(), sub),
        st.builds(lambda w, a, b: E.Until(lo_s=w[0], hi_s=w[1], left=a, right=b), windows(), sub, sub),
    )


# ---------------------------------------------------------------- faults and run specs

def _fault_targets(plan: ScenarioPlan, kind_cls) -> list[str]:
    """Targets the compiler accepts for this kind (each kind says which it takes)."""
    ego = plan.ego
    stack = STACKS.get(ego.stack.name)
    pool = kind_cls.valid_targets({s.name: s.name for s in ego.sensors}, stack)
    if kind_cls.target_kind == "site":
        settings = {k: v for k, v in ego.stack.settings.items() if isinstance(v, str)}
        pool = (pool - set(stack.fault_sites())) | set(stack.fault_sites(settings))
    return sorted(pool)


def _setting_value(spec):
    if spec.kind == "word":
        return st.sampled_from(spec.choices)
    lo = spec.low if spec.low is not None else -100.0
    hi = spec.high if spec.high is not None else 100.0
    if spec.kind == "int":
        return st.integers(int(lo), int(min(hi, 50))).map(float)
    return st.floats(lo, hi, allow_nan=False)


@st.composite
def concrete_faults(draw, plan: ScenarioPlan, max_faults: int = 4):
    out = []
    for i in range(draw(st.integers(0, max_faults))):
        cls = draw(st.sampled_from([c for c in FAULTS.classes() if _fault_targets(plan, c)]))
        target = draw(st.sampled_from(_fault_targets(plan, cls)))
        settings = {}
        for spec in cls.params:
            if spec.required or draw(st.booleans()):
                settings[spec.name] = draw(_setting_value(spec))
        settings = fitting_settings(cls, plan, target, settings)
        start = draw(st.floats(0.0, plan.duration_s))
        end = draw(st.one_of(st.none(), st.just(start), st.floats(start, plan.duration_s)))
        seed = draw(st.integers(0, 2**32 - 1))
        out.append(ConcreteFault(index=i, kind=cls.keyword, target=target, start_s=start, end_s=end,
                                 settings=settings, seed=seed))
    return out


def fitting_settings(cls, plan: ScenarioPlan, target: str, settings: dict) -> dict:
    """Without the settings the compiler refuses for this target sensor (an image fault's
    `lens` beyond the rig's cameras): the kind's own check decides."""
    problems_of = getattr(cls, "setting_problems", None)
    sensor = next((s for s in plan.ego.sensors if s.name == target), None)
    if problems_of is None or sensor is None:
        return settings
    sensor_settings = {p.name: p.default for p in SENSORS.get(target).params}
    sensor_settings |= {k: v.value for k, v in sensor.settings.items() if isinstance(v, E.Num)}
    defaults = {p.name: p.default for p in cls.params}
    bad = problems_of(defaults | {k: getattr(v, "value", v) for k, v in settings.items()}, target, sensor_settings)
    return {k: v for k, v in settings.items() if k not in bad}


@st.composite
def param_values(draw, plan: ScenarioPlan):
    for _ in range(50):
        params = {}
        for p in plan.params:
            if p.choices:
                params[p.name] = draw(st.sampled_from(p.choices))
            elif p.low is not None and p.high is not None:
                params[p.name] = draw(st.floats(p.low, p.high))
            else:
                params[p.name] = p.default
        if not violated_assumptions(plan, params):
            return params
    return plan.nominal_params()


@st.composite
def run_specs(draw, plans=None):
    """RunSpecs over the example plans with random parameters, faults and seeds."""
    plan = draw(st.sampled_from(plans or example_plans()))
    params = draw(param_values(plan))
    seed = draw(st.integers(0, 2**32 - 1))
    faults = draw(concrete_faults(plan))
    return RunSpec(plan=plan, params=params, seed=seed, faults=faults, run_id=draw(st.sampled_from(["", "c001-r002"])),
                   cell={}, repeat_index=0)


def is_finite_tree(expr) -> bool:
    return all(math.isfinite(n.value) for n in E.walk(expr) if isinstance(n, E.Num))


def judged(spec: RunSpec, robustness: dict[str, float], failures: tuple[Failure, ...] = (),
           drawn_values: dict[int, tuple[int, ...]] | None = None) -> RunResult:
    """What a synthetic judge returns: a finished run whose hard oracles have these
    robustness values, failing with these identities."""
    failed = {f.oracle: f for f in failures}
    result = RunResult.unfinished(spec, "ok", "", 0.0)
    for name in [*robustness, *(n for n in failed if n not in robustness)]:
        f = failed.get(name)
        result.verdicts.append(Verdict(name, "hard", robustness[name] if f is None else f.robustness, f is None,
                                       None if f is None else f.time_s, "" if f is None else f.mode))
    result.drawn_values = dict(drawn_values or {})
    return result
