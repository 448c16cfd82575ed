"""Dense traffic: a closed-loop run with the agents stepped by the kernel (`runtime.fleet`:
per run in declaration order, leaders from the members sorted by station), posed as arrays, with
the clearance broad phase and pybullet posed only when asked, gives the trace of the
brute-force loop (agents one by one, every actor scanned, every pair tested, every pose
handed to pybullet at once)."""

import math
from collections import Counter

import pytest

from addt_dsl.compiler import compile_source
from addt_dsl.runtime import agents as A
from addt_dsl.runtime import collision as C
from addt_dsl.runtime import execute as X
from addt_dsl.runtime.neighbours import LeaderIndex, leader_scan
from addt_dsl.runtime.world import PhysicsWorld, box_separation
from addt_dsl.sweep import expand

pytestmark = pytest.mark.slow


def dense(n_agents: int, reverse: bool = False, extra: str = "") -> str:
    """IDM cars on three lanes, in pairs at equal stations (leader ties, touching boxes),
    some changing lanes (leaders change), the ego among them. `reverse`: declared front
    to back (each leader declared before its follower: the sequential step's chains)."""
    agents = []
    for i in range(n_agents):
        slot = i // 2
        lane = -1 - slot % 3
        change = f"\n    after {1 + i % 3} s behavior lane_change to {-2 if lane != -2 else -1} duration 2 s" \
            if i % 4 == 1 else ""
        agents.append(f"  agent a{i} car on r lane {lane} at {40 + 12 * (slot // 3)} m speed {14 + i % 4} m/s {{\n"
                      f"    behavior idm speed {16 + i % 5} m/s{change}\n  }}")
    body = "\n".join(reversed(agents) if reverse else agents)
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
{extra}
}}"""


# A parked car (no behaviour: its rows step at 0 m/s^2) and one that drives off the
# road's end (posed by extrapolation).
EXTRAS = """  agent parked car on r lane -3 at 150 m speed 0 m/s
  agent leaving car on r lane -1 at 585 m speed 20 m/s {
    behavior idm speed 20 m/s
  }"""


def all_pairs(first, live, rows, sizes, touch):
    """`collision._clearances` without its broad phase: every pair of each live run in order,
    the separation as the loop before the kernel wrote it (math.hypot, box_separation)."""
    found = 0
    for k, run in enumerate(live.tolist()):
        lo, hi = int(first[run]), int(first[run + 1])
        boxes = [(*rows[i, :3].tolist(), *sizes[i].tolist()) for i in range(lo, hi)]
        reach = [0.5 * math.hypot(b[3], b[4]) for b in boxes]
        clear = [math.inf] * len(boxes)
        for a in range(len(boxes)):
            for b in range(a + 1, len(boxes)):
                dist = math.hypot(boxes[a][0] - boxes[b][0], boxes[a][1] - boxes[b][1])
                r = reach[a] + reach[b]
                sep = dist - r if dist > r + 5.0 else box_separation(boxes[a], boxes[b])
                clear[a], clear[b] = min(clear[a], sep), min(clear[b], sep)
                if sep <= 0.0:
                    if found < len(touch):
                        touch[found] = (k, a, b)
                    found += 1
        rows[lo:hi, -1] = [c if math.isfinite(c) else 1e3 for c in clear]
    return found


def brute_force(monkeypatch):
    """The per-agent loop with the reference lookups: agents stepped one by one, leaders
    found by scanning every actor, every pair tested, agents posed one at a time, every
    pose handed to pybullet at once."""
    eager, eager_many = PhysicsWorld.set_pose, PhysicsWorld.set_poses

    def set_pose_now(self, *args, **kwargs):
        eager(self, *args, **kwargs)
        self._sync_bodies()

    def set_poses_now(self, *args):
        eager_many(self, *args)
        self._sync_bodies()

    monkeypatch.setattr(A, "ARRAY_MIN_AGENTS", 10 ** 9)
    monkeypatch.setattr(A.Fleets, "_step_arrays", lambda self, items: items)  # every run to the per-agent loop
    monkeypatch.setattr(LeaderIndex, "leader", lambda self, agent: leader_scan(self.members, agent))
    monkeypatch.setattr(C, "_clearances", all_pairs)
    monkeypatch.setattr(PhysicsWorld, "set_pose", set_pose_now)
    monkeypatch.setattr(PhysicsWorld, "set_poses", set_poses_now)


@pytest.mark.parametrize("reverse", [False, True], ids=["declared-back-to-front", "declared-front-to-back"])
def test_array_step_gives_the_brute_force_trace(monkeypatch, reverse):
    result = compile_source(dense(24, reverse, EXTRAS))
    assert result.plan is not None, [str(d) for d in result.diagnostics]
    spec = expand(result.plan).specs[0]
    stepped = Counter()
    array_step = A.Fleets._step_arrays

    def counted(self, items):
        rest = array_step(self, items)
        stepped[not rest] += 1  # (one run: stepped by the kernel, or left to the per-agent loop)
        return rest

    with monkeypatch.context() as m:
        m.setattr(A.Fleets, "_step_arrays", counted)
        fast = X.execute(spec)
    assert fast.status == "ok", fast.error
    assert fast.trace.events_of("collision")  # the pairs start overlapping: contacts are exercised
    assert fast.trace.actors["leaving"].s[-1] > 600.0  # off the road's end
    # Every step the array plan allows is the kernel's, whatever the order of declaration
    # (a chain declared front to back too).
    assert stepped[True] > 0 and stepped[False] == 0, stepped

    brute_force(monkeypatch)
    brute = X.execute(spec)
    assert brute.digest == fast.digest
    assert brute.trace.events == fast.trace.events
    assert (brute.trace.object_count == fast.trace.object_count).all()
