"""Routes through junctions and both driving directions in short closed-loop runs."""

import math
from pathlib import Path

import numpy as np
import pytest

from addt_dsl.compiler import compile_file, compile_source
from addt_dsl.runtime.execute import execute
from addt_dsl.runtime.signals import compute_signals
from addt_dsl.sweep import expand
from tests.sim.conftest import EXAMPLES
from tests.sim.kit import first_run

pytestmark = pytest.mark.slow

MAPS = EXAMPLES / "maps"
ESMINI = Path(__file__).resolve().parents[2] / "data" / "esmini"


def run_text(text: str):
    out = first_run(text, "routes.addt", base_dir=EXAMPLES)
    assert out.status == "ok", out.error
    return out


def test_oncoming_lane_drives_against_s():
    out = run_text("""
scenario two_way {
  duration 4 s
  road r {
    line length 400 m
    lanes right 1 left 1
  }
  ego car on r lane -1 at 10 m speed 10 m/s
  agent oncoming car on r lane 1 at 300 m speed 12 m/s {
    behavior cruise speed 12 m/s
  }
}
""")
    a = out.trace.actors["oncoming"]
    assert a.speed[-1] == pytest.approx(12.0)
    assert a.x[-1] == pytest.approx(300.0 - 12.0 * 4.0, abs=0.2)  # towards -s with a positive speed
    assert a.y[0] == pytest.approx(1.75) and abs(math.remainder(a.heading[0] - math.pi, math.tau)) < 1e-9
    assert a.s[-1] - a.s[0] == pytest.approx(48.0, abs=0.2)  # its station grows as it drives


def test_agents_follow_their_route_through_the_junction():
    out = run_text("""
scenario turns {
  duration 14 s
  road town import "maps/fabriksgatan.xodr" road 0
  ego car on town route 2 lane -1 at 10 m speed 0 m/s {
    stack bev cruise_speed 0 m/s
  }
  agent lefty car on town route 0 -> left lane 1 at 60 m speed 8 m/s {
    behavior cruise speed 8 m/s
  }
  agent righty car on town route 0 -> right lane 1 at 60 m speed 8 m/s {
    behavior cruise speed 8 m/s
  }
}
""")
    left, right = out.trace.actors["lefty"], out.trace.actors["righty"]
    for track in (left, right):
        assert np.max(np.abs(track.lane_offset)) < 1e-6 and np.max(np.abs(track.t)) < 1e-6
        assert np.all(np.abs(np.diff(track.heading)) < 0.05)  # no jump between roads
    turn = lambda tr: math.remainder(tr.heading[-1] - tr.heading[0], math.tau)  # noqa: E731
    assert turn(left) == pytest.approx(math.pi / 2, abs=0.35) and turn(right) == pytest.approx(-math.pi / 2, abs=0.35)
    # Different routes: gap is Euclidean (centre distance less half lengths), not a station difference.
    sig = compute_signals(out.trace, {"gap(lefty,righty)", "distance(lefty,righty)"})
    assert np.allclose(sig["gap(lefty,righty)"], sig["distance(lefty,righty)"] - 4.6)


def test_the_ego_stack_drives_a_left_turn():
    plan = compile_file(EXAMPLES / "left_turn.addt").plan
    out = execute(expand(plan).specs[0])
    ego = out.trace.actors["ego"]
    assert out.status == "ok"
    assert np.max(np.abs(ego.t)) < 0.5  # keeps to the route lane through the turn
    assert math.remainder(ego.heading[-1] - ego.heading[0], math.tau) == pytest.approx(math.pi / 2, abs=0.35)
    assert out.digest == execute(expand(plan).specs[0]).digest


def test_the_merge_follows_the_ramp_into_the_highway():
    plan = compile_file(EXAMPLES / "ramp_merge.addt").plan
    out = execute(expand(plan).specs[0])
    merger = out.trace.actors["merger"]
    # Off the ramp (road 5 ends at x = 7.9 m) and in lane -2 of road 0 after the merge lane ends.
    assert merger.x[-1] > 100.0 and abs(merger.y[-1] - out.trace.actors["ego"].y[0]) < 5.0
    assert np.max(np.abs(merger.t)) < 1e-6


def test_a_lane_change_keeps_its_lane_where_the_route_lane_ends():
    """esmini's highway_merge: from the ramp (road 1 -> 5 -> 0, whose lane -3 narrows to
    nothing from s 75 to 100 m of road 0) into road 0's lane -2. The route's reference is
    the ramp lane's centre, then crosses over to lane -2 where it ends: the agent that
    changed into lane -2 stays there (esmini keeps lane and offset; it ended 3.5 m left, in
    lane -1, while it kept its offset from the reference). Past the crossing the reference
    is lane -2's centre: t = 0."""
    result = compile_source("""
scenario merge {
  duration 14 s
  road r1 import "xodr/soderleden.xodr" road 1
  road r0 import "xodr/soderleden.xodr" road 0
  ego car on r0 lane -1 at 300 m speed 0 m/s {
    stack bev cruise_speed 0 m/s
  }
  agent merger car on r1 route 1 -> 5 -> 0 lane -1 at 10 m speed 25 m/s {
    at 7 s behavior lane_change to -2 duration 2.8 s shape sinusoidal
  }
}
""", "merge.addt", base_dir=ESMINI)
    assert result.plan is not None, [str(d) for d in result.diagnostics]
    out = execute(expand(result.plan).specs[0])
    a = out.trace.actors["merger"]
    assert a.s[-1] > 166.6 + 121.0 + 10.0  # past road 1, road 5 and the crossing on road 0
    assert a.t[-1] == pytest.approx(0.0, abs=0.02)
    assert a.lane_offset[-1] == pytest.approx(0.0, abs=0.02)


@pytest.mark.parametrize("who", ["ego", "other"])
def test_actors_placed_at_the_end_of_their_first_road_start_in_its_lane(who):
    # Lane 1 of fabriksgatan's road 0 is driven against s: `at 0 m` is the end of the route's
    # first leg, where the path's station is the junction leg's start. The lane's direction
    # was read from that leg (driven along its s): lane 1 there has no centre, the start was
    # NaN and the run raised. The actor starts at road 0's lane 1 centre at s = 0 (the map's
    # geometry, parsed apart from the twin); the other one 30 m behind it.
    from addt_dsl.road.xodr import parse_xodr

    at = {"ego": "0 m", "other": "30 m"} if who == "ego" else {"ego": "30 m", "other": "0 m"}
    out = run_text(f"""
scenario at_the_end {{
  duration 1 s
  road town import "maps/fabriksgatan.xodr" road 0
  ego car on town route 0 -> straight lane 1 at {at["ego"]} speed 5 m/s
  agent other car on town route 0 -> left lane 1 at {at["other"]} speed 5 m/s {{
    behavior cruise speed 5 m/s
  }}
}}
""")
    x, y, _ = parse_xodr((MAPS / "fabriksgatan.xodr").read_text()).road("0").lane_center(1, 0.0)
    actor = out.trace.actors[who]
    # (the twin's roads are sampled: 0.14 mm from the exact geometry here)
    assert math.hypot(actor.x[0] - float(x), actor.y[0] - float(y)) < 1e-3
    assert np.isfinite(actor.x).all() and actor.s[-1] > actor.s[0] + 4.0
