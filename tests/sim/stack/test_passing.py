"""Passing a standing obstacle with the bev stack: within the lane when the obstacle
leaves room (a car parked 0.9 m into the lane), into a free lane of the same direction,
and through the oncoming lane only when it is seen clear for the whole manoeuvre (CARLA's
Slalom on a written road; docs/stack.md's passing rule), never into oncoming traffic."""

import math
from pathlib import Path

import numpy as np
import pytest

from addt_dsl.compiler import compile_source
from addt_dsl.runtime.execute import execute
from addt_dsl.sweep import expand
from tests.sim.kit import first_run

pytestmark = pytest.mark.slow

ROAD = """
scenario pass_it {
  duration 20 s
  road r {
    line length 500 m
    lanes LANES width 3.5 m
  }
  ego car on r lane -1 at 20 m speed 12 m/s goal 250 m {
    stack bev cruise_speed 12 m/s
  }
  agent parked car on r lane -1 at 150 m offset OFFSET speed 0 m/s
  ONCOMING
  expect {
    no collision
    reach goal within 20 s
  }
}
"""


def _run(lanes: str, offset: str, oncoming: str = ""):
    text = ROAD.replace("LANES", lanes).replace("OFFSET", offset).replace("ONCOMING", oncoming)
    return first_run(text, "pass.addt")


def test_a_car_parked_half_in_the_lane_is_passed_within_the_lane():
    """The parked car (1.9 m wide, centre 1.8 m right of the lane's) takes 0.9 m of the
    3.5 m lane: the ego moves left within its lane and passes (it stopped 23 m short)."""
    out = _run("right 1 left 1", "-1.8 m")
    assert out.passed, out.verdicts
    ego = out.trace.actors["ego"]
    # Its left side stays within 0.3 m past the centre line (t = 0; lane -1's centre -1.75 m).
    assert (ego.t + 0.5 * ego.width_m).max() < 0.3 + 0.05
    assert ego.t.max() > -1.75 + 0.4  # it did move over
    assert abs(ego.t[-1] + 1.75) < 0.2  # and back to the lane centre


def test_a_car_blocking_most_of_the_lane_is_passed_in_the_free_lane_beside():
    out = _run("right 2", "-1.0 m")
    assert out.passed, out.verdicts
    ego = out.trace.actors["ego"]
    assert ego.t.min() < -4.5  # in lane -2 (centre at t = -5.25 m) to pass


def test_never_into_the_oncoming_lane():
    """The parked car blocks the lane; an oncoming car comes: the ego waits behind the
    parked car, its left side never over the centre line by more than the in-lane margin."""
    out = _run("right 1 left 1", "0 m", "agent oncoming car on r lane 1 at 300 m speed 12 m/s {\n"
                                       "    behavior cruise speed 12 m/s\n  }")
    verdicts = {v.name: v.passed for v in out.verdicts}
    assert verdicts["no_collision"]
    ego = out.trace.actors["ego"]
    assert (ego.t + 0.5 * ego.width_m).max() < 0.3 + 0.05


# CARLA's Slalom (tests/data/carla/xosc/Slalom.xosc): containers 2 m long, 1 m wide (the
# catalogue obstacle's width), 1.7 m tall, in the ego's lane of a two-way road. Here three,
# centred in the lane (no room to pass within it), 12 m apart (passed as one group), with a
# lidar that sees a car head-on to 200 m (0.25 deg rays: `bev.lidar_sight`).
SLALOM = """
scenario slalom_like {
  duration 40 s
  road r {
    line length 500 m
    lanes right 1 left 1 width 3.5 m
  }
  ego car on r lane -1 at 20 m speed 8 m/s goal 260 m {
    stack bev cruise_speed 8 m/s
    SENSOR
  }
  agent c1 obstacle on r lane -1 at 120 m length 2 m width 1 m height 1.7 m
  agent c2 obstacle on r lane -1 at 132 m length 2 m width 1 m height 1.7 m
  agent c3 obstacle on r lane -1 at 144 m length 2 m width 1 m height 1.7 m
  ONCOMING
  expect {
    no collision
    reach goal within 40 s
  }
}
"""
FAR_LIDAR = "sensor lidar rays 1440 channels 5 vfov 4 deg pitch 2 deg range 200 m"


def _slalom(sensor: str = FAR_LIDAR, oncoming: str = ""):
    text = SLALOM.replace("SENSOR", sensor).replace("ONCOMING", oncoming)
    result = compile_source(text, "slalom.addt")
    assert result.ok, [d.message for d in result.diagnostics]
    return execute(expand(result.plan).specs[0])


def test_slalom_passes_through_the_empty_oncoming_lane_and_returns():
    out = _slalom()
    assert out.passed, out.verdicts
    ego = out.trace.actors["ego"]
    assert ego.t.max() > 1.0  # in the oncoming lane (centre at t = +1.75 m) to pass
    passing = ego.t > 0.0
    # Over the line only around the containers (rears 119-143 m): it returns after them. The
    # pass starts when c1's rear comes within 3 s x 8 m/s + 25 m of its front
    # (`PASS_START_S`, `PASS_START_M`); its centre crosses the line from 91 m.
    assert ego.s[passing].min() > 119.0 - 49.0 and ego.s[passing].max() < 175.0
    assert abs(ego.t[-1] + 1.75) < 0.2


def test_slalom_stays_behind_when_its_lidar_cannot_see_far_enough():
    """The default lidar sees a car head-on to 57 m; passing 3 containers takes ~60 m and
    ~8 s, in which an unseen car at 8 m/s comes ~80 m: the ego stays in its lane."""
    out = _slalom(sensor="")
    ego = out.trace.actors["ego"]
    assert {v.name: v.passed for v in out.verdicts}["no_collision"]
    assert (ego.t + 0.5 * ego.width_m).max() < 0.05  # its side stays in its lane
    assert ego.s.max() < 119.0  # behind the first container


def test_slalom_waits_for_the_oncoming_car_then_passes():
    """An oncoming car at 10 m/s is about 90 m off when the ego nears the containers: the ego
    waits in its lane (its side 0.3 m from the centre line, where it sees past them) until
    the car is by, then passes; it is never over the line while the car is ahead of it.
    Clearance oracle: 1 m (two cars 1.9 m wide in the centres of 3.5 m lanes pass 1.6 m
    apart; the waiting ego stands up to 0.5 m nearer the line)."""
    out = _slalom(oncoming="agent oncoming car on r lane 1 at 260 m speed 10 m/s {\n"
                           "    behavior cruise speed 10 m/s\n  }\n"
                           "  expect { clear_of_oncoming: always clearance(oncoming) > 1 m }")
    verdicts = {v.name: v.passed for v in out.verdicts}
    assert all(verdicts.values()), verdicts
    ego, car = out.trace.actors["ego"], out.trace.actors["oncoming"]
    # The road runs along x: the car (driving against s) has not gone by while its rear is
    # ahead of the ego's rear.
    ahead = car.x + 0.5 * car.length_m > ego.x - 0.5 * ego.length_m
    assert ahead[:100].all() and not ahead[-100:].any()
    assert (ego.t[ahead] + 0.5 * ego.width_m).max() < 0.05  # its side stays in its lane meanwhile
    assert ego.t.max() > 1.0  # and then it passes


# CARLA's Slalom as imported (tests/data/carla: Town01, road 24, the ego in lane 1 driving
# against s on its route, 4 m lanes, the oncoming lane the road's driving lane -1; a 0.3 m
# shoulder and a sidewalk on each side). The five containers of the file are replaced by three
# centred in the ego's lane, 12 m apart (CARLA's stand at and across the centre line: see
# `test_imported_slalom_waits_behind_its_containers_whatever_comes`).
def _town01_slalom(oncoming: str = "", containers: bool = False):
    from addt_dsl.interop.openscenario.importer import import_xosc

    carla = Path(__file__).resolve().parents[2] / "data" / "carla"
    got = import_xosc(carla / "xosc" / "Slalom.xosc", maps=[carla / "maps"], lenient=True)
    lines = [ln for ln in got.text.splitlines() if containers or not ln.lstrip().startswith("agent c")]
    text = "\n".join(lines).replace("stack bev cruise_speed 11.176 m/s",
                                    "stack bev cruise_speed 11.176 m/s\n    " + FAR_LIDAR)
    if not containers:
        mine = "".join(f"  agent k{i} obstacle on r24 lane 1 at {s} m length 2 m width 1 m height 1.7 m\n"
                       for i, s in enumerate((79.67, 67.67, 55.67)))
        text = text.replace("  environment {", mine + oncoming + "  environment {")
    result = compile_source(text, "slalom.addt", base_dir=carla / "maps")
    assert result.ok, [d.message for d in result.diagnostics]
    return execute(expand(result.plan).specs[0])


def test_town01_slalom_passes_through_the_roads_other_driving_lane_and_returns():
    """Was a stop 2.3 m behind the first container with the rule holding: the lane
    preference counted lane -1 -> 1 as two lanes (ids skip 0), and back at its lane centre
    the container hid more of the oncoming lane, so the rule flickered while it crept up."""
    out = _town01_slalom()
    verdicts = {v.name: v.passed for v in out.verdicts}
    assert verdicts["no_collision"] and verdicts["driven_distance"], verdicts
    ego = out.trace.actors["ego"]
    # Path frame: t = 0 the ego lane's centre, the centre line at +2 m, lane -1's centre at
    # +4 m and its outer edge at +6 m (then the shoulder): it drives in that lane, no further.
    assert ego.t.max() > 3.5 and (ego.t + 0.5 * ego.width_m).max() < 6.0
    passing = ego.t > 1.0
    # Over the line only around the containers (path stations of their rears 28-52 m).
    assert ego.s[passing].min() > 5.0 and ego.s[passing].max() < 110.0
    back = (ego.s > 100.0) & (ego.s < 250.0)  # road 24's end, the junction, road 23 (the run ends in a corner)
    assert np.abs(ego.t[back]).max() < 0.2  # back in its lane


def test_town01_slalom_waits_for_the_oncoming_car_then_passes():
    """An oncoming car on lane -1 at s = 30 m, 10 m/s, is 75.7 m ahead of the ego's centre
    (the ego's at s = 105.67 m). Hand check of the rule at the start, with the first container
    only in sight (it hides the two behind it): its front at 30.3 m (path), the end of the pass
    30.3 + 5 + 2.25 (half the ego) + 25.15 (0.75 of a 33.5 m return at 11.176 m/s) - 3.3 =
    59.4 m of travel from standstill at 2 m/s^2 to 11.176 m/s: 31.2 m in 5.59 s, then 2.52 s,
    T = 8.11 s; the car's near end (73.4 m) must stay beyond 61.65 m (the ego's front at the
    end) over T + 2 s: 73.4 - 10 x 10.11 = -27.7 m < 61.65 m. The gap would need the car
    162.8 m off, beyond road 24's 109 m: the ego waits until the car is by, then passes."""
    out = _town01_slalom(oncoming="  agent oncoming car on r24 lane -1 at 30 m speed 10 m/s {\n"
                                  "    behavior cruise speed 10 m/s\n  }\n"
                                  "  expect { clear_of_oncoming: always clearance(oncoming) > 1 m }\n")
    verdicts = {v.name: v.passed for v in out.verdicts}
    assert verdicts["no_collision"] and verdicts["driven_distance"] and verdicts["clear_of_oncoming"], verdicts
    ego, car = out.trace.actors["ego"], out.trace.actors["oncoming"]
    # The ego drives towards +y, the car towards -y: the car has not gone by while its rear
    # (high y) is beyond the ego's rear (low y).
    ahead = car.y + 0.5 * car.length_m > ego.y - 0.5 * ego.length_m
    assert ahead[:50].all() and not ahead[-50:].any()
    assert (ego.t[ahead] + 0.5 * ego.width_m).max() < 2.0  # its side stays in its lane meanwhile
    assert ego.t.max() > 3.5  # and then it passes


# CARLA's Slalom as the file places it (tests/data/carla/xosc/Slalom.xosc, with the default
# sensor set the importer gives its ego).
CARLA = Path(__file__).resolve().parents[2] / "data" / "carla"
WAIT_S = 88.67  # [m] road 24's station of the ego's centre, its front 9.55 m short of c3 (path station 17.0)


def _slalom_file(sensor: str = "", extra: str = "", duration_s: float = 300.0, ego_s: float | None = None):
    from addt_dsl.interop.openscenario.importer import import_xosc

    text = import_xosc(CARLA / "xosc" / "Slalom.xosc", maps=[CARLA / "maps"], lenient=True).text
    if ego_s is not None:
        start = "at 105.670311036 m speed 0 m/s offset -0.022265274 m"
        assert start in text
        text = text.replace(start, f"at {ego_s} m speed 0 m/s offset -0.03 m")
    text = text.replace("stack bev cruise_speed 11.176 m/s", "stack bev cruise_speed 11.176 m/s\n    " + sensor)
    text = text.replace("  environment {", extra + "  environment {")
    text = text.replace("duration 300 s", f"duration {duration_s} s")
    result = compile_source(text, "slalom.addt", base_dir=CARLA / "maps")
    assert result.ok, [d.message for d in result.diagnostics]
    return expand(result.plan).specs[0]


def _at_start(spec, read):
    from addt_dsl.runtime import phases
    from addt_dsl.runtime.agents import Fleets
    from addt_dsl.runtime.state import RunState

    run = RunState(spec)
    try:
        phases.clock([run], [0.0])
        phases.pose([run], [0.0], Fleets())
        return read(run)
    finally:
        run.close()


def test_slaloms_fourth_container_leaves_no_way_within_the_lane():
    """c4 stands across the right half of the ego's lane (its 2 m length across the road, 1.59
    to 3.59 m from the centre line of road 24's 4 m lanes): 1.59 m between it and the centre
    line, 0.41 m between it and the lane's outer edge, for a hero 2.1 m wide. Any way past it
    takes the body 0.51 m over the centre line (or 1.69 m over the outer edge): the scenario's
    own `keep_lane` (ScenarioRunner's KeepLaneTest, failed on any lane marking crossed) fails
    whenever `driven_distance` (70 m, past the containers) passes."""
    from addt_dsl.road import parse_xodr
    from addt_dsl.runtime.fastroad import FastRoad

    xodr = CARLA / "maps" / "Town01.xodr"
    road = FastRoad(parse_xodr(xodr.read_text(), str(xodr)).road("24"))
    c4 = _at_start(_slalom_file(), lambda run: run.fleet.ground_truth("c4"))
    s = 69.67
    rx, ry, rh = road.reference_pose(s)
    line = 0.5 * (float(road.lane_center_t(1, s)) + float(road.lane_center_t(-1, s)))
    width = float(road.lane_center_t(1, s)) - float(road.lane_center_t(-1, s))
    ts = []
    for along in (-0.5, 0.5):
        for across in (-0.5, 0.5):
            x = c4.x + along * c4.length_m * math.cos(c4.heading) - across * c4.width_m * math.sin(c4.heading)
            y = c4.y + along * c4.length_m * math.sin(c4.heading) + across * c4.width_m * math.cos(c4.heading)
            ts.append(-(x - rx) * math.sin(rh) + (y - ry) * math.cos(rh) - line)
    assert width == pytest.approx(4.0)
    assert min(ts) == pytest.approx(1.59, abs=0.01) and max(ts) == pytest.approx(3.59, abs=0.01)
    hero = 2.1
    assert min(ts) < hero and width - max(ts) < hero


@pytest.mark.parametrize("ahead_m", [20.0, 40.0, 79.0])
def test_a_car_behind_slaloms_containers_is_hidden_below_their_top_and_seen_over_it(ahead_m):
    """Occlusion with heights, measured with the twin's rays: a car standing in the oncoming
    lane `ahead_m` ahead of the waiting ego (its centre 9.55 m behind c3's rear). The default
    lidar (1 m mount, level to 4 deg down) and a 200 m one on the same mount meet it with no
    ray (c3, 1.7 m tall, reaching 0.4 m over the centre line, hides it: no ray of theirs rises
    above 1 m); CARLA's leaderboard lidar on a 2.5 m roof (64 channels, +10 to -30 deg, 85 m)
    meets it over the containers with the two rays perception needs."""
    roof = "sensor lidar rays 937 channels 64 vfov 40 deg pitch 10 deg range 85 m z 2.5 m"
    extra = f"  agent k car on r24 lane -1 at {WAIT_S - ahead_m} m speed 0 m/s\n"

    def rays_on_k(run):
        frame = next(iter(run.sensors.values())).capture(run, 0.0)
        return [run.physics.body_names.get(int(b)) for b in frame.data["hit_body"]].count("k")

    got = {name: _at_start(_slalom_file(sensor, extra, ego_s=WAIT_S), rays_on_k)
           for name, sensor in (("default", ""), ("far", FAR_LIDAR), ("roof", roof))}
    assert got["default"] == got["far"] == 0 and got["roof"] >= 2, got


def test_imported_slalom_rolls_up_and_waits_at_a_steady_point():
    """Default sensors, no traffic: the ego rolls up past c1 at the 2 m/s crawl and waits about
    11 m short of c3 (where the crawl's 5 s path would come within 2 m of it) without
    creeping: the containers' tracked velocities stay near 0 (standing, seen with 0.1 m noise
    and their velocity by ground-truth perception), so c3 stays a blocker. Before the
    tracker's filter it crept on (14.6 m short of c3 after 30 s, 2.3 m after 300 s): a tracked
    velocity across the road of up to 1.5 m/s made c3 crossing every few cycles."""
    out = execute(_slalom_file(duration_s=40.0))
    ego = out.trace.actors["ego"]
    front = ego.s + 0.5 * ego.length_m
    k10 = int(10.0 / 0.01)  # it is there by 10 s
    assert front[k10] - ego.length_m > 9.3 + 1.0  # its rear past c1's front (c1 centred at 9.3 m, 2 m long)
    assert 9.0 < 28.8 - front[-1] < 12.0  # ~11 m short of c3's rear (path station 28.8 m)
    assert front[-1] - front[k10] < 0.5  # and stays there


def test_imported_slalom_waits_behind_its_containers_whatever_comes():
    """The file as imported, default sensors: it passes c1 within its lane and stays behind
    c3 (c3 hides the oncoming lane beyond about 16 m; the pass needs 186 m seen clear,
    `test_carlas_slalom_needs_the_oncoming_lane_seen_clear_to_186_m`), its body never over
    the centre line, while a car comes at 10 m/s in the oncoming lane, hidden behind the
    containers until it is by them."""
    oncoming = ("  agent oncoming car on r24 lane -1 at 5 m speed 10 m/s {\n"
                "    behavior cruise speed 10 m/s\n  }\n")
    out = execute(_slalom_file(extra=oncoming, duration_s=20.0))
    verdicts = {v.name: v.passed for v in out.verdicts}
    assert verdicts["no_collision"] and verdicts["keep_lane"] and not verdicts["driven_distance"], verdicts
    ego, car = out.trace.actors["ego"], out.trace.actors["oncoming"]
    # Path frame: t = 0 the ego lane's centre, the centre line at +2 m.
    assert (ego.t + 0.5 * ego.width_m).max() < 2.0
    # It never reaches c3's rear (path station 28.8 m); it creeps up to 2.4 m short of it, where it
    # should wait ~10 m back: the tracker's velocity noise moves the wait point (docs/stack.md).
    assert (ego.s + 0.5 * ego.length_m).max() < 28.8 - 2.0
    # The car goes by (it passes c1, which stands in its lane, 0.1 m off): 1 m or more between
    # their sides (centres 3 m apart side by side).
    assert car.y[0] > ego.y[0] and car.y[-1] < ego.y[-1]  # ahead at first (the ego drives towards +y), then by
    assert np.hypot(ego.x - car.x, ego.y - car.y).min() > 0.5 * (2.1 + 1.9) + 1.0
