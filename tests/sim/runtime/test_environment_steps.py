"""Environment changes during a run: `at T MODEL ...` replaces the model's settings from its
start on (what the sensors see changes then, not before), `when C then MODEL ...` fires on
the state; a time of day sets the sun's elevation."""

import math

import numpy as np
import pytest

from addt_dsl.compiler import compile_source
from addt_dsl.printer import print_plan
from addt_dsl.runtime.environment import Light, sun_elevation
from addt_dsl.runtime.execute import execute
from addt_dsl.sweep import expand
from tests.sim import kit

pytestmark = pytest.mark.slow

SCENE = """
scenario env_change {
  duration 4 s
  road r {
    line length 400 m
    lanes right 1
  }
  ego car on r lane -1 at 10 m speed 10 m/s {
    stack bev cruise_speed 10 m/s
    sensor lidar
  }
  agent lead car ahead of ego 40 m speed 10 m/s {
    behavior cruise speed 10 m/s
  }
  environment {
ENV
  }
}
"""


def _run(env: str):
    result = compile_source(SCENE.replace("ENV", env), "env.addt")
    assert result.ok, [str(d) for d in result.diagnostics]
    out = execute(expand(result.plan).specs[0])
    assert out.status == "ok", out.error
    return result.plan, out.trace


def test_fog_from_a_time_on_hides_the_lead_from_then_only():
    _, tr = _run("    at 2 s fog visibility 30 m")
    seen = np.asarray(tr.object_count) >= 1
    t = np.asarray(tr.time)
    assert seen[(t > 0.3) & (t < 2.0)].all()  # clear air: the lead 40 m ahead is seen
    assert not seen[t > 2.3].any()  # fog of 30 m visibility: it is not (docs/twin.md's lidar equation)
    events = [e for e in tr.events if e.kind == "environment"]
    assert [(e.time_s, e.detail["model"]) for e in events] == [(2.0, "fog")]


def test_a_change_replaces_the_declared_model_and_a_condition_starts_one():
    _, tr = _run("    fog visibility 30 m\n    at 2 s fog visibility 10 km\n"
                 "    when s(ego) >= 40 m then rain rate 1 mm/h")
    seen = np.asarray(tr.object_count) >= 1
    t = np.asarray(tr.time)
    assert not seen[t < 2.0].any()
    assert seen[t > 2.3].all()  # the fog lifted at 2 s; light rain leaves the lead in sight
    kinds = [(e.time_s, e.detail["model"]) for e in tr.events if e.kind == "environment"]
    assert [k for _, k in kinds] == ["fog", "rain"]
    assert kinds[0][0] == 2.0 and kinds[1][0] == pytest.approx(3.0, abs=0.02)  # 30 m at 10 m/s


def test_environment_steps_print_and_read_back():
    plan, _ = _run("    light time 6.5 h latitude 48 deg\n    at 2 s fog visibility 30 m\n"
                   "    when rising objects() >= 1 delayed 0.5 s then light sun -10 deg")
    text = print_plan(plan)
    assert "at 2 s fog visibility 30 m" in text
    again = compile_source(text, "again.addt")
    assert again.ok, [str(d) for d in again.diagnostics]
    assert again.plan.environment == plan.environment
    assert again.plan.environment_steps == plan.environment_steps


def test_time_of_day_gives_the_sun_elevation():
    # Hand values: at noon on the equinox (declination ~0) the sun stands 90 deg - latitude
    # high; at midnight of the June solstice at 45 deg N, -(90 - 45 - 23.44) deg.
    assert math.degrees(sun_elevation(12 * 3600.0, math.radians(45.0), 80.0)) == pytest.approx(45.0, abs=0.5)
    assert math.degrees(sun_elevation(0.0, math.radians(45.0), 172.0)) == pytest.approx(-21.56, abs=0.05)
    dawn = Light({"time": 6.0 * 3600.0, "latitude": math.radians(45.0), "day": 80.0})
    noon = Light({"time": 12.0 * 3600.0, "latitude": math.radians(45.0), "day": 80.0})
    assert dawn.ambient() < 0.1 < noon.ambient() == 1.0


@pytest.mark.parametrize("line, code", [
    ("light latitude 48 deg", "E0105"),  # neither sun nor time
    ("light sun 10 deg time 12 h", "E0204"),  # both
    ("at 2 s fgo visibility 30 m", "E0106"),
    ("fog visibility 30 m\n    fog visibility 50 m", "E0102"),
    ("when s(ego) > 20 m repeat 2 then fog visibility 30 m", "E0204"),
])
def test_bad_environment_lines_are_diagnostics(line, code):
    result = compile_source(SCENE.replace("ENV", "    " + line), "env.addt")
    assert not result.ok
    assert code in [d.code for d in result.diagnostics], [str(d) for d in result.diagnostics]


def test_environment_steps_survive_export_and_import(tmp_path):
    from addt_dsl.compiler import compile_file
    from addt_dsl.interop.openscenario.importer import import_xosc
    from addt_dsl.interop.xosc_export import export_run
    from tests.conftest import ROOT

    spec = expand(compile_file(ROOT / "tests" / "data" / "interop" / "every_environment.addt").plan).specs[0]
    done = export_run(spec, tmp_path, "env")
    got = import_xosc(done.xosc_path)
    assert got.text is not None, [d.message for d in got.diagnostics]
    back = compile_source(got.text, "back.addt", base_dir=tmp_path)
    assert back.ok, [str(d) for d in back.diagnostics]
    plan = spec.plan

    def models(clauses):
        return sorted((c.name, sorted((k, round(float(v.value), 9)) for k, v in c.settings.items())) for c in clauses)

    assert models(back.plan.environment) == models(plan.environment)
    # A top-level step is armed at 0 s: `after 4 s` and `at 4 s` are the same start.
    steps = [(t.at_s or t.after_s, t.condition is not None, models([t.clause])) for t in plan.environment_steps]
    again = [(t.at_s or t.after_s, t.condition is not None, models([t.clause])) for t in back.plan.environment_steps]
    assert again == steps
    a, b = execute(spec), execute(expand(back.plan).specs[0])
    assert [e for e in a.trace.events if e.kind == "environment"] == \
        [e for e in b.trace.events if e.kind == "environment"]


# An ego following a slower lead on a two-lane road, with the blocks the test fills in.
CONDITION_SCENE = """scenario t {{
  duration 3 s
  road r {{
    line length 400 m
    lanes right 2
  }}
  ego car on r lane -1 at 40 m speed 8 m/s {{
    stack bev cruise_speed 8 m/s
  }}
  variables {{
    {variables}
  }}
  environment {{
    {environment}
  }}
  agent lead car on r lane -1 at 70 m speed 5 m/s {{
    {lead}
  }}
}}
"""


def test_an_environment_step_reads_a_variable_as_an_actors_step_does():
    # `var(P)` in an environment step's condition read 0 (the variables were recorded after
    # the environment's steps fired), so this change never came; now it comes with the
    # lead's step, one sample after the variable is set.
    tr = kit.run(CONDITION_SCENE.format(variables="phase = 0\n    at 1 s set phase 1",
                                        environment="when var(phase) == 1 then fog visibility 30 m",
                                        lead="when var(phase) == 1 then behavior cruise speed 12 m/s"))
    fired = {e.kind: e.time_s for e in tr.events if e.kind in ("environment", "behavior")}
    assert fired == {"environment": pytest.approx(1.01), "behavior": pytest.approx(1.01)}
    assert tr.variables["phase"][100] == 0.0 and tr.variables["phase"][101] == 1.0


def test_environment_and_variable_steps_read_the_clearance_of_their_sample():
    # Their steps fired before the collision phase had written the sample's clearance, so
    # they read 0 m: `clearance(ego) < 5 m` held at 0 s with the lead 16 m ahead.
    def fired(close: str):
        tr = kit.run(CONDITION_SCENE.format(
            variables=f"close = 0\n    when clearance(ego) < {close} then set close 1",
            environment=f"when clearance(ego) < {close} then fog visibility 30 m",
            lead="behavior cruise speed 5 m/s"))
        return tr, {e.kind: e.time_s for e in tr.events if e.kind in ("environment", "variable")}

    tr, got = fired("5 m")
    assert tr.actors["ego"].clearance.min() > 5.0 and got == {}
    tr, got = fired("20 m")  # the clearance closes from 25 m: below 20 m at 2.12 s
    k = int(np.argmax(tr.actors["ego"].clearance < 20.0))
    assert k > 0 and got == {"environment": tr.time[k], "variable": tr.time[k]}
