"""Traffic lights and stop signs reach the `bev` stack behind the bridge (protocol 3) as they
reach it in process: the same run, bit for bit (docs/bridge.md claims the same digest). The
reference server answered `stop_line_ahead` and `stop_sign_ahead` with None before, so the
stack behind the bridge drove through the red light and the stop sign it stops for in process."""

from pathlib import Path

import numpy as np
import pytest

from addt_dsl.compiler import compile_source
from addt_dsl.runtime.execute import execute
from addt_dsl.stack.bridge_server import start_in_thread
from addt_dsl.sweep import expand
from tests.sim.runtime.test_lights_closed_loop import INLINE
from tests.sim.runtime.test_stop_signs import MAP, SIGNS, SOURCE

pytestmark = pytest.mark.slow

EXAMPLES = Path(__file__).resolve().parents[3] / "examples"


@pytest.fixture(scope="module")
def server():
    srv = start_in_thread()
    yield srv
    srv.shutdown()
    srv.server_close()


def _bridged(spec, address: str):
    """The same RunSpec with the ego's `stack bev ...` as `stack external ...` at `address`."""
    stack = spec.plan.ego.stack
    remote = stack.model_copy(update={"name": "external", "settings": {**stack.settings, "address": address}})
    plan = spec.plan.model_copy(update={"ego": spec.plan.ego.model_copy(update={"stack": remote})})
    return spec.model_copy(update={"plan": plan})


def _both(source: str, server, path: str = "<input>", base_dir=EXAMPLES):
    result = compile_source(source, path, base_dir=base_dir)
    assert result.ok, [str(d) for d in result.diagnostics]
    spec = expand(result.plan).specs[0]
    local, remote = execute(spec), execute(_bridged(spec, server.address))
    assert local.status == remote.status == "ok", remote.error
    return local, remote


def _same_run(local, remote) -> None:
    a, b = local.trace.actors["ego"], remote.trace.actors["ego"]
    assert np.array_equal(a.x, b.x) and np.array_equal(a.y, b.y)  # the same path, bit for bit
    assert [(v.name, v.passed, v.robustness) for v in remote.verdicts] == \
        [(v.name, v.passed, v.robustness) for v in local.verdicts]
    assert remote.digest == local.digest


# test_lights_closed_loop's inline light (green 5 s, yellow 3 s, red from 8 s at 150 m), as its
# program turns it red, and as light steps set it red at 1 s and hand it back to the program at
# 4 s (state changes the run's script makes, not a function of time the remote could know).
@pytest.mark.parametrize("steps", ["", "at 1 s light main state red\n    at 4 s light main state program"])
def test_a_light_turning_red_holds_the_bridged_stack_as_in_process(server, steps):
    local, remote = _both(INLINE.replace("STEPS", steps), server)
    _same_run(local, remote)
    ego = remote.trace.actors["ego"]
    front = ego.s + 0.5 * ego.length_m
    assert front.max() <= 150.0 and ego.speed[-1] < 0.1  # it waits at the red light, before the line
    assert {v.name: v.passed for v in remote.verdicts}["no_red_light"]


def test_a_light_on_the_route_through_a_junction_holds_the_bridged_stack(server):
    # red_light_runner with the ego where the stopper was: road 3's light on its route (left
    # turn onto road 2), red from 4 s; the stop line's station is the route's.
    text = (EXAMPLES / "red_light_runner.addt").read_text().replace(
        "ego car on town route 2 -> straight -> 0 lane -1 at 250 m",
        "ego car on town route 3 -> left -> 2 lane -1 at 10 m").replace(
        "agent stopper car on town route 3 -> left -> 2 lane -1 at 10 m",
        "agent stopper car on town route 2 -> straight -> 0 lane -1 at 250 m")
    assert "ego car on town route 3" in text and "stopper car on town route 2" in text
    local, remote = _both(text, server, "route_light.addt")
    _same_run(local, remote)
    assert remote.trace.actors["ego"].speed[-1] < 0.1
    assert {v.name: v.passed for v in remote.verdicts}["no_red_light"]


def test_a_stop_sign_stops_the_bridged_stack_as_in_process(server, tmp_path):
    # test_stop_signs' map: a stop sign for the ego's direction at 150 m, one for the other at 300 m.
    (tmp_path / "signs.xodr").write_text(MAP.read_text().replace("<signals>\n        </signals>", SIGNS))
    local, remote = _both(SOURCE, server, "stop_sign.addt", tmp_path)
    _same_run(local, remote)
    ego = remote.trace.actors["ego"]
    front = ego.s + 0.5 * ego.length_m
    assert np.where(front <= 150.0, ego.speed, np.inf).min() < 0.05  # it stood before the line
    assert front[-1] > 200.0  # and went on
    stops = [e for e in remote.trace.events if e.kind == "stop_sign"]
    assert len(stops) == 1 and stops[0].detail["station_m"] == pytest.approx(150.0, abs=1e-6)
    assert {v.name: v.passed for v in remote.verdicts}["no_stop_sign"]


def test_a_priority_sign_gives_the_bridged_stack_the_right_of_way_as_in_process(server, tmp_path):
    # test_priority_signs' scene: a priority sign on the ego's approach, the side car braking
    # to a stop at its yield sign; behind the bridge without the sign's kind the ego slowed
    # for the side car (every approach gives way).
    from tests.sim.runtime.test_priority_signs import spec

    local_spec = spec(tmp_path, "306", 52.0, True)
    local, remote = execute(local_spec), execute(_bridged(local_spec, server.address))
    assert local.status == remote.status == "ok", remote.error
    _same_run(local, remote)
    assert remote.trace.actors["ego"].speed.min() > 7.9
