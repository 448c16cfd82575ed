"""Yield and priority signs of a map in closed loop (runtime/signs.py, the `bev` stack's gap
rule): at fabriksgatan's junction the ego comes from the south (road 0, lane 1) and goes
straight on north; a side car comes from the west (road 3, lane -1) and goes straight on
east, crossing the ego's path. The ego's route enters the junction at station 93.66 m
(road 0's s = 0; it starts 60 m before it, at station 33.66 m). Signs, written into the
map's `<signals>`: on the ego's approach (road 0, s 3 m, facing its lane) a yield (205) or
a priority-road (306) sign; on the side car's (road 3, s 111 m) a yield sign."""

from pathlib import Path

import numpy as np
import pytest

from addt_dsl.compiler import compile_source
from addt_dsl.runtime.execute import execute
from addt_dsl.sweep import expand

pytestmark = pytest.mark.slow

MAP = Path(__file__).resolve().parents[3] / "examples" / "maps" / "fabriksgatan.xodr"
ENTRY_U = 93.66  # [m] the ego's route station of the junction entry
YIELD_SPEED = 20.0 / 3.6  # [m/s] bev's YIELD_SIGN_SPEED
SIGN = '<signal s="{s}" t="{t}" id="{id}" dynamic="no" orientation="{o}" type="{type}"/>'


def _map(ego_sign: str | None) -> str:
    """fabriksgatan.xodr with a sign of type `ego_sign` on the ego's approach (none: None)
    and a yield sign on the side car's."""
    text = MAP.read_text()
    signs = {"0": SIGN.format(s=3.0, t=4.0, id=900, o="-", type=ego_sign) if ego_sign else "",
             "3": SIGN.format(s=111.0, t=-4.0, id=901, o="+", type="205")}
    for road_id, sign in signs.items():
        start = text.index("<signals>", text.index(f'id="{road_id}" junction="-1"'))
        text = text[:start] + "<signals>" + sign + text[text.index("</signals>", start):]
    return text


def spec(tmp_path, ego_sign: str | None, side_at: float, side_stops: bool):
    """The RunSpec of the scene: a sign of type `ego_sign` on the ego's approach, the side
    car starting at station `side_at` [m], braking to a stop before its line if `side_stops`."""
    (tmp_path / "signs.xodr").write_text(_map(ego_sign))
    stop = "    when s(side) > 99 m then behavior brake decel 3 m/s^2\n" if side_stops else ""
    source = f"""
scenario signs {{
  duration 20 s
  road town import "signs.xodr" road 0
  ego car on town route 0 -> straight lane 1 at 60 m speed 8 m/s goal 150 m {{
    stack bev cruise_speed 8 m/s
  }}
  agent side car on town route 3 -> straight lane -1 at {side_at} m speed 8 m/s {{
    behavior cruise speed 8 m/s
{stop}  }}
  expect {{
    no collision
    reach goal within 20 s
  }}
}}
"""
    result = compile_source(source, "signs.addt", base_dir=tmp_path)
    assert result.ok, [str(d) for d in result.diagnostics]
    return expand(result.plan).specs[0]


def _run(tmp_path, ego_sign: str | None, side_at: float, side_stops: bool):
    out = execute(spec(tmp_path, ego_sign, side_at, side_stops))
    assert out.status == "ok", out.error
    assert all(v.passed for v in out.verdicts), out.verdicts
    return out.trace


def _at_entry(ego) -> int:
    return int(np.argmax(ego.s + 0.5 * ego.length_m >= ENTRY_U))


def test_behind_a_yield_sign_without_conflict_the_ego_slows_but_does_not_stop(tmp_path):
    # The side car crosses the ego's path long after the ego (it starts 94 m before its entry).
    ego = _run(tmp_path, "205", 20.0, False).actors["ego"]
    k = _at_entry(ego)
    assert ego.speed[k] <= YIELD_SPEED + 0.01  # 20 km/h at the entry (8 m/s without the sign)
    assert ego.speed.min() > 5.0  # no stop, no wait


def test_behind_a_yield_sign_the_ego_lets_the_crossing_car_pass_then_goes(tmp_path):
    trace = _run(tmp_path, "205", 52.0, False)
    ego, side = trace.actors["ego"], trace.actors["side"]
    k = _at_entry(ego)
    assert ego.speed[k] <= YIELD_SPEED + 0.01
    # It waits (down to a crawl before the junction) while the side car comes, and crosses
    # the side car's lane (y > -8.5 m: its north edge, by the run's positions) only once
    # the side car has passed the ego's lane (x > 31 m).
    assert ego.speed[:k].min() < 3.0
    j = int(np.argmax(ego.y > -8.5))
    assert side.x[j] > 31.0


def test_behind_a_priority_sign_the_ego_goes_through_while_the_side_car_stops(tmp_path):
    trace = _run(tmp_path, "306", 52.0, True)
    ego, side = trace.actors["ego"], trace.actors["side"]
    # Without reading the sign (main before it) the ego slowed to 3.2 m/s for the side car braking to its line.
    assert ego.speed.min() > 7.9
    # The ego enters the side car's lane while the side car brakes west of the junction
    # (x < 15 m), where it stops.
    j = int(np.argmax(ego.y > -8.5))
    assert side.x[j] < 15.0 and side.speed[j] < side.speed[0]
    assert side.x.max() < 15.0 and side.speed[-1] < 0.1


def test_behind_a_priority_sign_the_ego_still_yields_to_a_car_that_ignores_its_sign(tmp_path):
    # The side car drives through its yield sign at 8 m/s: once it could no longer stop at
    # 2.5 m/s^2 the ego waits for it (no collision: `_run` checks the verdicts).
    trace = _run(tmp_path, "306", 52.0, False)
    ego, side = trace.actors["ego"], trace.actors["side"]
    assert ego.speed.min() < 1.0
    j = int(np.argmax(ego.y > -8.5))
    assert side.x[j] > 31.0
