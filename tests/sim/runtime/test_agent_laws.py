"""Agents whose behaviours have an array law (`Behavior.array_law`: IDM, cruise, brake, walk
along the lane) are stepped by the agents' kernel (`fleet.step`), also after a `when ...
then behavior` switch and once a shaped speed change is over, and give the trace of the
per-agent loop (`RunState.move`, each behaviour's `accel`) bit for bit, alone and batched."""

from collections import Counter

import pytest

from addt_dsl.compiler import compile_source
from addt_dsl.runtime import agents as A
from addt_dsl.runtime.execute import execute, execute_batch
from addt_dsl.sweep import expand
from tests.sim.runtime.test_batch import full_digest

pytestmark = pytest.mark.slow

# A cruising lead that brakes hard at a station (a `when` switch) and a follower on IDM
# behind it; a car that brakes to a speed and cruises again later; a car that changes
# lanes while it cruises (with a vehicle's rate bound); one walking along its lane (a slow
# rider); one without a behaviour. `SHAPED` adds a cruise whose speed change is shaped
# over a time: the loop steps its run until the change is over, the kernel from then on.
LAWS = """
scenario laws {
  duration 6 s
  param brake_at = 90 m in [60 m, 120 m]
  road r {
    line length 400 m
    arc length 200 m curvature 0.004 /m
    lanes right 3 width 3.5 m
  }
  ego car on r lane -2 at 20 m speed 15 m/s {
    stack bev cruise_speed 18 m/s
    sensor lidar rate 10 Hz rays 360 range 80 m
  }
  agent lead car on r lane -2 at 60 m speed 14 m/s {
    behavior cruise speed 16 m/s
    when lead.s > brake_at then behavior brake decel 7 m/s^2
  }
  agent follower car on r lane -2 at 40 m speed 15 m/s {
    behavior idm speed 18 m/s
  }
  agent slowing car on r lane -1 at 50 m speed 20 m/s {
    behavior brake decel 3 m/s^2 to_speed 8 m/s
    after 3 s behavior cruise speed 14 m/s accel 3 m/s^2
  }
  agent changing car on r lane -3 at 30 m speed 12 m/s {
    behavior cruise speed 20 m/s accel 4 m/s^2 max_accel 2.5 m/s^2
    after 1 s behavior lane_change to -2 duration 2 s
  }
  agent rider cyclist on r lane -3 at 70 m speed 3 m/s {
    behavior walk speed 5 m/s accel 0.7 m/s^2
  }
  agent parked car on r lane -1 at 150 m speed 0 m/s
  sweep {
    grid brake_at in [70, 100] m
  }
%s
}"""
SHAPED = """  agent shaped car on r lane -1 at 120 m speed 10 m/s {
    behavior cruise speed 18 m/s shape cubic duration 2 s
  }"""


def specs(extra: str = ""):
    result = compile_source(LAWS % extra)
    assert result.plan is not None, [str(d) for d in result.diagnostics]
    return expand(result.plan).specs


def one_by_one(monkeypatch, specs_):
    """Each run alone, every agent stepped and posed one by one (the per-agent loop)."""
    with monkeypatch.context() as m:
        m.setattr(A, "ARRAY_MIN_AGENTS", 10 ** 9)
        m.setattr(A.Fleets, "_step_arrays", lambda self, items: items)
        return [full_digest(execute(s)) for s in specs_]


def counted(monkeypatch) -> Counter:
    """Run-steps the kernel stepped (True) and left to the loop (False), from now on."""
    seen = Counter()
    step = A.Fleets.step

    def count(self, runs, ts):
        rest = step(self, runs, ts)
        seen[False] += len(rest)
        seen[True] += len(runs) - len(rest)
        return rest

    monkeypatch.setattr(A.Fleets, "step", count)
    return seen


def test_cruise_brake_walk_and_switches_step_as_arrays_with_the_loops_bits(monkeypatch):
    runs = specs()
    alone = one_by_one(monkeypatch, runs)
    seen = counted(monkeypatch)
    arrays = [full_digest(execute(s)) for s in runs]
    assert arrays == alone
    assert seen[True] > 0 and seen[False] == 0, seen  # every step, before and after the switches
    got = execute_batch(runs + runs[::-1])
    assert [full_digest(r) for r in got] == alone + alone[::-1]
    braked = [e for e in got[0].trace.events if e.kind == "behavior" and e.detail["behavior"] == "brake"
              and e.detail["actor"] == "lead"]
    assert braked and braked[0].time_s > 0.0  # (the `when` switch happened during the run)
    assert got[0].trace.actors["lead"].speed[-1] < 5.0


def test_shaped_speed_change_goes_to_the_kernel_once_over(monkeypatch):
    runs = specs(SHAPED)[:1]
    alone = one_by_one(monkeypatch, runs)
    seen = counted(monkeypatch)
    assert [full_digest(execute(s)) for s in runs] == alone
    dt = runs[0].plan.step_s
    # the 2 s change one by one (its last step's law is the shape's), the rest by the kernel
    assert seen[False] == pytest.approx(2.0 / dt, abs=2) and seen[True] > 0, seen
