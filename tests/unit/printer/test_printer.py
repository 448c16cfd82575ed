"""The printer: compile(print(x)) gives x back (up to provenance), for plans and runs."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from tests.unit.search.search_testkit import (ROOT, example_plans, fitting_settings, formulas, kitchen_sink_plan,
                                              run_specs)

from addt_dsl import expr as E
from addt_dsl import units
from addt_dsl.compiler import compile_source
from addt_dsl.diagnostics import render_text
from addt_dsl.limits import DEFAULT
from addt_dsl.plan import ClausePlan, OraclePlan, TriggerPlan
from addt_dsl.printer import (PrinterError, compile_pinned, format_const, format_expr, format_quantity, pin_spec,
                              print_plan, print_spec, semantic_key)
from addt_dsl.registry import SIGNALS
from addt_dsl.sweep import expand

FAST = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])


# A printed plan imports its maps by file name (the printer writes them beside it as side
# files); the examples' maps are all in examples/maps.
MAPS = Path(__file__).resolve().parents[3] / "examples" / "maps"


def _recompile(text: str):
    # Cost thresholds are not what these tests are about: a plan whose settings sit mid-range
    # (a 968 x 548 camera at 30 Hz) is printed and read back like any other.
    result = compile_source(text, path="printed.addt", base_dir=MAPS, limits=DEFAULT.raised(allow_large=True))
    assert result.ok, render_text(result.diagnostics, result.sources) + "\n" + text
    return result.plan


def _body(text: str) -> str:
    return "\n".join(line for line in text.splitlines() if not line.startswith("#"))


@pytest.mark.parametrize("keep_user_text", [True, False])
@pytest.mark.parametrize("index", range(len(example_plans())))
def test_plan_round_trip(index, keep_user_text):
    plan = example_plans()[index]
    text = print_plan(plan, keep_user_text=keep_user_text)
    assert semantic_key(_recompile(text)) == semantic_key(plan)


def test_user_text_is_kept_where_it_reads_back():
    plan = kitchen_sink_plan()
    text = print_plan(plan)
    assert "safe: (speed(ego) < 30 m/s until within 3 s s(ego) > 20 m) implies" in text
    assert "comfort: always abs(accel(ego)) < 3 m/s^2" in text
    assert "assume gap > 12 m and v_lead < 24 m/s" in text


def test_sweep_expands_the_same_runs():
    plan = kitchen_sink_plan()
    again = _recompile(print_plan(plan))
    assert [semantic_key(s) for s in expand(again).specs] == [semantic_key(s) for s in expand(plan).specs]


@FAST
@given(run_specs())
def test_pinned_run_round_trip(spec):
    """compile(print(spec)) is the one run of the pinned plan: same RunSpec, bit for bit."""
    text = print_spec(spec)
    again = compile_pinned(text, base_dir=MAPS)
    assert semantic_key(again) == semantic_key(pin_spec(spec))
    assert again.seed == spec.seed
    assert again.plan.sweep == type(spec.plan.sweep)()
    assert [f.model_dump(exclude={"index"}) for f in again.faults] == \
        [f.model_dump(exclude={"index"}) for f in pin_spec(spec).faults]


@FAST
@given(run_specs())
def test_printing_a_pinned_run_is_a_fixed_point(spec):
    pinned = pin_spec(spec)
    assert semantic_key(pin_spec(pinned)) == semantic_key(pinned)
    again = compile_pinned(print_spec(spec), base_dir=MAPS)
    assert _body(print_spec(again)) == _body(print_spec(spec))


@FAST
@given(run_specs())
def test_pinning_keeps_what_the_run_sees(spec):
    pinned = pin_spec(spec)
    used = {n: spec.params[n] for n in pinned.params}
    assert pinned.params == used
    assert pinned.seed == spec.seed
    assert [(f.kind, f.target, f.start_s, f.end_s, f.seed) for f in pinned.faults] == \
        [(f.kind, f.target, f.start_s, f.end_s, f.seed) for f in spec.faults]
    assert [f.index for f in pinned.faults] == list(range(len(spec.faults)))


def _param_dims(plan):
    return {p.name: units.DIMENSIONS_BY_NAME[p.dimension] for p in plan.params}


@settings(max_examples=75, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(formulas(_param_dims(kitchen_sink_plan())), min_size=1, max_size=3), st.data())
def test_formulas_round_trip(generated, data):
    """Random well-typed formulas, as oracles and as a trigger condition, print and read back."""
    plan = kitchen_sink_plan()
    oracles = [OraclePlan(name=f"gen_{i}", severity=data.draw(st.sampled_from(["hard", "warn"])), formula=f)
               for i, f in enumerate(generated)]
    goal = plan.oracles[-1]
    lead = plan.agents[0]
    # Trigger conditions are checked at each instant: only formulas without temporal
    # operators and without signals of the run's past (`jerk`, `travelled`) qualify.
    instant = [f for f in generated if not any(
        isinstance(n, (E.Temporal, E.Until))
        or isinstance(n, E.Signal) and SIGNALS.get(n.name.split("(")[0]).history for n in E.walk(f))]
    if instant:
        trigger = TriggerPlan(condition=instant[0], clause=ClausePlan(keyword="behavior", name="brake", settings={}))
        lead = lead.model_copy(update={"triggers": [*lead.triggers, trigger]})
    plan = plan.model_copy(update={"oracles": [*plan.oracles[:-1], *oracles, goal],
                                   "agents": [lead, *plan.agents[1:]]})
    text = print_plan(plan, keep_user_text=False)
    assert semantic_key(_recompile(text)) == semantic_key(plan)


@pytest.mark.parametrize("value,dim,text", [
    (12.5, units.SPEED, "12.5 m/s"),
    (-2.0, units.DIMENSIONLESS, "-2"),
    (0.03490658503988659, units.ANGLE, "2 deg"),
    (0.1, units.ANGLE, "0.1 rad"),
    (0.002, units.CURVATURE, "0.002 1/m"),
    (1e-05, units.TIME, "1e-05 s"),
    (float("inf"), units.LENGTH, "1e999 m"),
    # Float noise of a unit conversion: the unit that writes it short and exactly.
    (50 * 1000.0 / 3600.0, units.SPEED, "50 km/h"),
    (120 / 3.6, units.SPEED, "120 km/h"),
    (0.1 * 38, units.LENGTH, "380 cm"),  # 3.8000000000000003 m, which 380 cm reads back as
    # Noise with no exact short form stays exact (a pinned run reads back bit for bit).
    (0.1 + 0.2, units.LENGTH, "0.30000000000000004 m"),
    (0.1 + 0.2, units.DIMENSIONLESS, "0.30000000000000004"),
])
def test_quantities(value, dim, text):
    assert format_quantity(value, dim) == text
    assert units.to_si(float(text.split()[0]), text.split()[1] if " " in text else None)[0] == value


@FAST
@given(st.floats(allow_nan=False, allow_infinity=False, min_value=-1e9, max_value=1e9),
       st.sampled_from([units.SPEED, units.LENGTH, units.TIME, units.ANGLE, units.ACCELERATION]))
def test_every_quantity_reads_back_bit_for_bit(value, dim):
    text = format_quantity(value, dim)
    number, symbol = text.split(" ", 1)
    assert units.to_si(float(number), symbol)[0] == value, text


def test_an_imported_speed_in_km_h_prints_as_km_h():
    """esmini's acc-test.xosc states 120 km/h as 33.333333333333336 m/s: the import writes `120 km/h`."""
    from addt_dsl.interop.openscenario.importer import import_xosc

    root = ROOT / "tests" / "data" / "esmini"
    got = import_xosc(root / "xosc" / "acc-test.xosc", root=root)
    assert got.text is not None
    assert "33.333333333333336" not in got.text and "120 km/h" in got.text


def test_a_free_product_puts_the_unit_where_it_can_be_written():
    # sqrt(0) cannot carry a length (its operand would need m^2): the other factor does.
    f = E.Binary(op="<", left=E.Signal(name="clearance(ego)"),
                 right=E.Binary(op="*", left=E.Call(fn="sqrt", args=(E.Num(value=4.0),)), right=E.Num(value=2.0)))
    assert format_expr(f) == "clearance(ego) < sqrt(4) * 2 m"
    # Both sides free: `objects() * 0 < accel(ego) * 0` needs a unit on the right's 0, not the left's.
    g = E.Binary(op="<", left=E.Binary(op="*", left=E.Signal(name="objects()"), right=E.Num(value=0.0)),
                 right=E.Binary(op="*", left=E.Signal(name="accel(ego)"), right=E.Num(value=0.0)))
    assert format_expr(g) == "objects() * 0 m/s^2 < accel(ego) * 0"


def test_compound_constants_use_unit_products():
    assert format_const(6.0, units.LENGTH * units.TIME) == "6 m * 1 s"
    assert format_const(2.0, units.LENGTH / units.MASS) == "2 m / 1 kg"
    assert format_const(2.0, units.DIMENSIONLESS / (units.MASS * units.LENGTH)) == "2 / 1 m / 1 kg"


def test_formula_layout():
    gap = E.Signal(name="gap(ego,lead)")
    f = E.Binary(op="and", left=E.Temporal(op="always", arg=E.Binary(op=">", left=gap, right=E.Num(value=5.0))),
                 right=E.Unary(op="not", arg=E.Temporal(op="eventually", lo_s=1.0, hi_s=2.0,
                                                        arg=E.Num(value=1.0))))
    assert format_expr(f) == "(always gap(ego, lead) > 5 m) and not (eventually during [1 s, 2 s] true)"
    nested_until = E.Until(left=E.Num(value=1.0), right=E.Until(left=E.Num(value=1.0), right=E.Num(value=-1.0)))
    assert format_expr(nested_until) == "true until (true until false)"
    assert format_expr(E.Binary(op="-", left=E.Num(value=1.0), right=E.Num(value=-3.0)), units.LENGTH) == "1 m - -3 m"


def test_subtraction_reads_back():
    plan = kitchen_sink_plan()
    closing = E.Binary(op="-", left=E.Signal(name="speed(ego)"), right=E.Signal(name="speed(lead)"))
    minus = E.Binary(op="<", left=closing, right=E.Num(value=1.0))
    oracle = OraclePlan(name="closing", formula=E.Temporal(op="always", arg=minus))
    plan = plan.model_copy(update={"oracles": [oracle, *plan.oracles]})
    assert semantic_key(_recompile(print_plan(plan, keep_user_text=False))) == semantic_key(plan)


def test_unprintable_things_are_errors_not_wrong_text():
    with pytest.raises(PrinterError):
        format_expr(E.Unary(op="neg", arg=E.Num(value=3.0)), units.LENGTH)
    with pytest.raises(PrinterError):
        format_quantity(float("nan"), units.LENGTH)
    plan = kitchen_sink_plan()
    with pytest.raises(PrinterError):
        print_plan(plan.model_copy(update={"oracles": plan.oracles[:-1]}))  # goal without its oracle


def test_compound_parameter_reads_back():
    source = ("scenario s {\n  duration 1 s\n  road r {\n    line length 50 m\n  }\n"
              "  param area = 6 m * 1 s in [2 m * 1 s, 8 m * 1 s]\n  param inv = 2 / 1 kg\n"
              "  ego car on r lane -1 at 0 m\n  expect {\n    always area > 1 m * 1 s and inv > 0 / 1 kg\n  }\n}\n")
    plan = _recompile(source)
    assert semantic_key(_recompile(print_plan(plan, keep_user_text=False))) == semantic_key(plan)


def _sample_setting(spec):
    from addt_dsl.plan import num

    if spec.kind in ("word",):
        return spec.choices[0] if spec.choices else None
    if spec.kind in ("name", "string"):
        return None
    if spec.kind == "list":  # two increasing items (a speed profile's times must increase)
        base = spec.low + 1.0 if spec.low is not None else 1.0
        return [num(base), num(base + 1.0)]
    if spec.low is not None and spec.high is not None:
        value = (spec.low + spec.high) / 2
    elif spec.default is not None and not isinstance(spec.default, str):
        value = float(spec.default)
    elif spec.low is not None:
        value = spec.low + 1.0
    else:
        value = 1.0
    return num(float(round(value)) if spec.kind == "int" else value)


def _clause(keyword, cls):
    settings = {}
    for spec in cls.params:
        value = "ego" if spec.kind == "name" and spec.required else _sample_setting(spec)
        if value is not None:
            settings[spec.name] = value
    # Settings that exclude each other (`distance` or `time_gap`): drop the one the class names.
    validate = getattr(cls, "validate", None)
    def plain(v):
        return [plain(i) for i in v] if isinstance(v, list) else getattr(v, "value", v)

    while validate is not None and (problems := validate({k: plain(v) for k, v in settings.items()})):
        settings.pop(problems[0][0])
    return ClausePlan(keyword=keyword, name=cls.keyword, settings=settings)


def test_every_registered_behaviour_sensor_and_fault_prints():
    """A new registry entry prints without touching the printer (its settings are data)."""
    from addt_dsl.registry import BEHAVIORS, FAULTS, SENSORS, STACKS

    plan = kitchen_sink_plan()
    lead = plan.agents[0]
    agents = [lead.model_copy(update={"name": f"a_{cls.keyword}", "behaviors": [_clause("behavior", cls)],
                                      "triggers": []})
              for cls in BEHAVIORS.classes()]
    ego = plan.ego.model_copy(update={"sensors": [_clause("sensor", cls) for cls in SENSORS.classes()]})
    sensors = [s.name for s in ego.sensors]
    faults = []
    for cls in FAULTS.classes():
        clause = _clause("fault", cls)
        accepts = cls.valid_targets({name: name for name in sensors}, STACKS.get(ego.stack.name))
        target = (next(n for n in sensors if n in accepts) if cls.target_kind == "sensor"
                  else {"site": "control.steer", "node": "planner"}[cls.target_kind])
        settings = fitting_settings(cls, plan.model_copy(update={"ego": ego}), target, clause.settings)
        faults.append(plan.faults[0].model_copy(update={"kind": cls.keyword, "target": target,
                                                        "settings": settings}))
    oracles = [o for o in plan.oracles if not E.signals_used(o.formula) & {"distance(ego,lead)", "ttc(ego,lead)",
                                                                            "gap(ego,lead)", "speed(lead)"}]
    plan = plan.model_copy(update={"agents": agents, "ego": ego, "faults": faults, "oracles": oracles})
    assert semantic_key(_recompile(print_plan(plan, keep_user_text=False))) == semantic_key(plan)


def test_a_scripted_ego_prints_back_with_every_behaviour():
    """The ego driven by each registered behaviour (no stack, no sensors, no faults: a
    scripted ego without a stack has none), and by a step, reads back as the same plan."""
    from addt_dsl.registry import BEHAVIORS

    plan = kitchen_sink_plan()
    lead = plan.agents[0]
    for cls in BEHAVIORS.classes():
        clause = _clause("behavior", cls)
        clause = clause.model_copy(update={"settings": {k: lead.name if v == "ego" else v
                                                        for k, v in clause.settings.items()}})
        step = TriggerPlan(at_s=E.Num(value=2.0), clause=clause)
        ego = plan.ego.model_copy(update={"behaviors": [clause], "triggers": [step], "stack": None, "sensors": []})
        scripted = plan.model_copy(update={"ego": ego, "faults": []})
        assert scripted.ego.scripted
        again = _recompile(print_plan(scripted, keep_user_text=False))
        assert again.ego.stack is None and again.ego.sensors == []
        assert semantic_key(again) == semantic_key(scripted), cls.keyword


# -- routes and poses on a map: what the printer writes must read back as the same plan

def _route_plan(route: list[str], lane: int, yaw_rad: float):
    plan = next(p for p in example_plans() if any(a.route for a in p.actors()))
    ego = plan.ego.model_copy(update={"route": route, "lane": E.Num(value=float(lane)),
                                      "yaw": E.Num(value=yaw_rad) if yaw_rad else None})
    return plan.model_copy(update={"ego": ego, "sweep": plan.sweep.model_copy(update={"grid": []})})


# Routes of fabriksgatan.xodr's ego road (0, driven in lane 1 into junction 4), fully expanded.
ROUTES = (["0"], ["0", "8", "1"], ["0", "9", "2"], ["0", "10", "3"])


@FAST
@given(st.sampled_from(ROUTES), st.floats(min_value=-3.0, max_value=3.0, allow_nan=False))
def test_routes_and_yaw_round_trip(route, yaw_rad):
    plan = _route_plan(route, 1, yaw_rad)
    again = _recompile(print_plan(plan, keep_user_text=False))
    assert again.ego.route == route
    assert semantic_key(again) == semantic_key(plan)


@FAST
@given(st.text(alphabet="ab_Z09 -.\"\\", min_size=1, max_size=8))
def test_any_road_id_prints_as_one_route_stop(road_id):
    from addt_dsl.compiler.parser import parse_source
    from addt_dsl.diagnostics import DiagnosticSink
    from addt_dsl.printer.plan import format_route_stop

    text = f"scenario s {{\n  ego car on r route 1 -> {format_route_stop(road_id)} lane -1 at 0 m\n}}\n"
    source = parse_source(text, "r.addt", DiagnosticSink())
    actor = next(d for d in source.scenarios[0].definitions if hasattr(d, "route"))
    assert actor.route.stops == ("1", road_id)


NAMED_STEPS = """
scenario named {
  duration 10 s
  road r {
    line length 300 m
    lanes right 2
  }
  ego car on r lane -1 at 10 m speed 10 m/s
  agent lead car on r lane -1 at 50 m speed 10 m/s {
    %s: at 2 s behavior brake decel 4 m/s^2 to_speed 5 m/s
    %s: when ended(lead.%s) then sequence {
      behavior lane_change to -2 duration 2 s
      %s: parallel {
        behavior cruise speed 8 m/s
      }
    }
  }
  agent other car on r lane -2 at 20 m {
    when started(lead.%s) and not ended(lead.%s) for 0.5 s then behavior cruise speed 12 m/s
  }
  expect {
    went: eventually ended(lead.%s) or started(lead.%s)
  }
}
"""

labels = st.from_regex(r"[a-z][a-z0-9_]{0,8}", fullmatch=True).filter(
    lambda w: w not in {"at", "after", "when", "then", "behavior", "behaviour", "sequence", "parallel",
                        "set", "sensor", "stack", "lane", "and", "or", "not", "ended", "started"})


@FAST
@given(st.lists(labels, min_size=3, max_size=3, unique=True))
def test_named_steps_and_their_states_round_trip(names):
    """Labels on steps and groups, and `started(...)`/`ended(...)` in triggers and oracles,
    print back to the same plan."""
    a, b, c = names
    result = compile_source(NAMED_STEPS % (a, b, a, c, c, b, b, a), path="named.addt")
    assert result.ok, render_text(result.diagnostics, result.sources)
    text = print_plan(result.plan, keep_user_text=False)
    assert f"{a}: at 2 s" in text and f"{c}: parallel {{" in text and f"ended(lead.{a})" in text
    assert semantic_key(_recompile(text)) == semantic_key(result.plan)


# -- traffic lights: signals, controllers with programs, light steps, the oracle and signal

LIGHT_STATES_WORDS = ("green", "yellow", "red", "program")


@st.composite
def _lights_scenario(draw) -> str:
    n_signals = draw(st.integers(1, 3))
    signals = [f"    signal s{i} road r at {draw(st.integers(10, 290))} m"
               + draw(st.sampled_from(["", " lane -1", " lane -2"])) for i in range(n_signals)]
    members = draw(st.lists(st.sampled_from([f"s{i}" for i in range(n_signals)]), min_size=1, max_size=3,
                            unique=True))
    times = [f"{key} {draw(st.integers(0, 40))} s" for key in ("green", "yellow", "red", "offset")
             if draw(st.booleans())]
    green = draw(st.sampled_from(["", " green g"]))  # a program time may be a parameter
    steps = []
    for _ in range(draw(st.integers(0, 3))):
        start = draw(st.sampled_from(["at {t} s", "after {t} s", "when distance(ego, lead) < {t} m then",
                                      "at {t} s when light(main) == red then"])).format(t=draw(st.integers(1, 9)))
        steps.append(f"    {start} light main state {draw(st.sampled_from(LIGHT_STATES_WORDS))}")
    bare = ["    light main state red"] if draw(st.booleans()) else []
    run = " at_red run" if draw(st.booleans()) else ""
    cycle = " ".join(t for t in times if not (green and t.startswith("green")))
    return f"""scenario lit {{
  duration 10 s
  road r {{
    line length 300 m
    lanes right 2
  }}
  param g = 10 s in [5 s, 20 s]
  lights {{
{chr(10).join(signals)}
    controller main signals [{', '.join(members)}] {cycle}{green}
{chr(10).join(bare + steps)}
  }}
  ego car on r lane -1 at 10 m speed 10 m/s
  agent lead car on r lane -2 at 40 m speed 8 m/s{run}
  expect {{
    no red_light
    always light(main) == green or speed(ego) >= 0 m/s
  }}
}}
"""


@FAST
@given(_lights_scenario())
def test_lights_round_trip(source):
    result = compile_source(source, path="lit.addt")
    assert result.ok, render_text(result.diagnostics, result.sources) + "\n" + source
    plan = result.plan
    for keep_user_text in (True, False):
        again = _recompile(print_plan(plan, keep_user_text=keep_user_text))
        assert semantic_key(again) == semantic_key(plan)
        assert again.controllers == plan.controllers and again.light_steps == plan.light_steps


def test_map_controllers_print_their_signal_ids():
    source = """scenario lit {
  duration 10 s
  road town import "fabriksgatan_traffic_lights.xodr" road 3
  lights {
    controller west signals [1, 2, 3] red 25 s
  }
  ego car on town lane -1 at 20 m speed 5 m/s
}
"""
    plan = compile_source(source, path="lit.addt", base_dir=MAPS).plan
    text = print_plan(plan)
    assert "controller west road town signals [1, 2, 3] red 25 s" in text
    assert semantic_key(_recompile(text)) == semantic_key(plan)


NEW_CONSTRUCTS = """
scenario esmini_constructs {
  duration 6 s
  road r {
    line length 300 m
    lanes right 2
  }
  ego car on r lane -2 at 10 m speed 10 m/s at_road_end stop {
    behavior cruise speed 10 m/s
    when road_edge(ego) < 0 m for 1 s then behavior lane_change to -2 duration 2 s
  }
  agent a car on r lane -1 at 20 m speed 10 m/s at_road_end stop {
    moves: when rising var(phase) > 10 then behavior lane_offset to -1.5 m max_lat_accel 2 m/s^2 shape cubic
    at 4 s behavior lane_offset to 0.5 m duration 1 s
  }
  variables {
    phase = 2
    at 3 s set phase 11
    when speed(ego) > 30 m/s then set phase -1
  }
}
"""


def test_lane_offsets_road_ends_and_variables_round_trip():
    plan = compile_source(NEW_CONSTRUCTS, path="new.addt").plan
    assert plan is not None
    text = print_plan(plan, keep_user_text=False)
    assert "variables {" in text and "at 3 s set phase 11" in text and "at_road_end stop" in text
    assert semantic_key(_recompile(text)) == semantic_key(plan)
