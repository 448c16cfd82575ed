"""Dense traffic: a closed-loop run with the fast lookups (sorted leader index, clearance
broad phase, pybullet posed only when asked) gives the trace of the brute-force ones
(every actor scanned, every pair tested, every pose handed to pybullet at once)."""

import math

import pytest

from addt_dsl.compiler import compile_source
from addt_dsl.runtime import execute as X
from addt_dsl.runtime.neighbours import LeaderIndex, leader_scan
from addt_dsl.runtime.world import PhysicsWorld
from addt_dsl.sweep import expand

pytestmark = pytest.mark.slow


def dense(n_agents: int) -> str:
    """IDM cars on three lanes, in pairs at equal stations (leader ties, touching boxes),
    some changing lanes (leaders change), the ego among them."""
    agents = []
    for i in range(n_agents):
        slot = i // 2
        lane = -1 - slot % 3
        change = f"\n    after {1 + i % 3} s behavior lane_change to {-2 if lane != -2 else -1} duration 2 s" \
            if i % 4 == 1 else ""
        agents.append(f"  agent a{i} car on r lane {lane} at {40 + 12 * (slot // 3)} m speed {14 + i % 4} m/s {{\n"
                      f"    behavior idm speed {16 + i % 5} m/s{change}\n  }}")
    body = "\n".join(agents)
    return f"""
scenario dense {{
  duration 4 s
  road r {{
    line length 400 m
    arc length 200 m curvature 0.004 /m
    lanes right 3 width 3.5 m
  }}
  ego car on r lane -2 at 20 m speed 15 m/s {{
    stack bev cruise_speed 18 m/s
    sensor lidar rate 10 Hz rays 360 range 80 m
  }}
{body}
}}"""


def all_pairs(run, names, boxes):
    """Every pair, in order: the clearance loop without its broad phase."""
    reach = {n: 0.5 * math.hypot(boxes[n][3], boxes[n][4]) for n in names}
    return [(a, b, X._pair_separation(a, b, boxes[a], boxes[b], reach[a], reach[b]))
            for i, a in enumerate(names) for b in names[i + 1:]]


def test_fast_lookups_give_the_brute_force_trace(monkeypatch):
    result = compile_source(dense(24))
    assert result.plan is not None, [str(d) for d in result.diagnostics]
    spec = expand(result.plan).specs[0]
    fast = X.execute(spec)
    assert fast.status == "ok", fast.error
    assert fast.trace.events_of("collision")  # the pairs start overlapping: contacts are exercised

    eager = PhysicsWorld.set_pose

    def set_pose_now(self, *args, **kwargs):
        eager(self, *args, **kwargs)
        self._sync_bodies()

    monkeypatch.setattr(LeaderIndex, "leader", lambda self, agent: leader_scan(self.members, agent))
    monkeypatch.setattr(X, "_pair_separations", all_pairs)
    monkeypatch.setattr(PhysicsWorld, "set_pose", set_pose_now)
    brute = X.execute(spec)
    assert brute.digest == fast.digest
    assert brute.trace.events == fast.trace.events
