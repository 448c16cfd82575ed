"""Named steps closed-loop: `ended(...)`/`started(...)` follow what each behaviour does
(OpenSCENARIO StoryboardElementStateCondition), and a step waiting on another one's end
starts within one physics step of it."""

import numpy as np
import pytest

from addt_dsl.runtime.signals import STEP_ENDED, STEP_STARTED
from tests.sim import kit

pytestmark = pytest.mark.slow

TEMPLATE = """
scenario steps {{
  duration {duration} s
  road r {{
    line length 800 m
    lanes right 3 width 3.5 m
  }}
  ego car on r lane -2 at 10 m speed 0 m/s {{
    stack bev cruise_speed 0 m/s
  }}
{agents}
}}
"""


def run(agents: str, duration: float = 8.0):
    return kit.run(TEMPLATE.format(agents=agents, duration=duration))


def first(trace, step: str, state: int) -> int | None:
    hits = np.flatnonzero(trace.steps[step] >= state)
    return int(hits[0]) if len(hits) else None


def test_a_step_starts_on_the_sample_the_other_one_ends():
    tr = run("""agent lead car on r lane -1 at 80 m speed 10 m/s {
  brake_hard: at 1 s behavior brake decel 5 m/s^2 to_speed 2 m/s
}
agent follower car on r lane -1 at 40 m speed 10 m/s {
  go: when ended(lead.brake_hard) then behavior cruise speed 4 m/s
}""")
    started = first(tr, "lead.brake_hard", STEP_STARTED)
    ended = first(tr, "lead.brake_hard", STEP_ENDED)
    assert started == round(1.0 / tr.period_s)
    # The brake ends when the lead is at its `to_speed`: 8 m/s off at 5 m/s^2 is 1.6 s.
    assert ended * tr.period_s == pytest.approx(2.6, abs=tr.period_s + 1e-9)
    assert tr.actors["lead"].speed[ended] == pytest.approx(2.0, abs=1e-3)
    assert tr.actors["lead"].speed[ended - 1] > 2.0 + 1e-3
    assert first(tr, "follower.go", STEP_STARTED) == ended  # within one step: the same sample
    assert tr.actors["follower"].speed[ended] == pytest.approx(10.0)  # acts from the next step
    assert tr.actors["follower"].speed[ended + 1] < 10.0


def test_each_behaviour_ends_as_documented():
    tr = run("""agent changer car on r lane -1 at 100 m speed 10 m/s {
  lc: at 1 s behavior lane_change to -2 duration 3 s
}
agent profiled car on r lane -3 at 100 m {
  prof: at 0.5 s behavior speed_profile times [0, 2, 4] s speeds [0, 6, 3] m/s
}
agent grouped car on r lane -3 at 200 m speed 5 m/s {
  both: at 1 s parallel {
    behavior cruise speed 8 m/s accel 2 m/s^2
    behavior lane_change to -2 duration 2 s
  }
}
agent follower car on r lane -1 at 20 m speed 5 m/s {
  endless: at 0.5 s behavior idm speed 8 m/s
}""", duration=7.0)
    dt = tr.period_s
    # A lane change ends when it reaches the lane: `duration` after it starts.
    lc = first(tr, "changer.lc", STEP_ENDED)
    assert lc * dt == pytest.approx(4.0, abs=dt + 1e-9)
    assert tr.actors["changer"].t[lc] == pytest.approx(-5.25, abs=0.01)
    # A speed profile ends at its last point.
    assert first(tr, "profiled.prof", STEP_ENDED) * dt == pytest.approx(4.5, abs=dt + 1e-9)
    # A group ends when all its steps have: the cruise at 2.5 s, the lane change at 3 s.
    assert first(tr, "grouped.both", STEP_ENDED) * dt == pytest.approx(3.0, abs=dt + 1e-9)
    # Car following has no natural end.
    assert first(tr, "follower.endless", STEP_STARTED) is not None
    assert first(tr, "follower.endless", STEP_ENDED) is None


def test_a_replaced_behaviour_never_ends():
    tr = run("""agent lead car on r lane -1 at 80 m speed 10 m/s {
  slow: at 1 s behavior brake decel 2 m/s^2
  at 2 s behavior cruise speed 10 m/s
}""")
    assert first(tr, "lead.slow", STEP_STARTED) is not None
    assert first(tr, "lead.slow", STEP_ENDED) is None


def test_a_named_cruise_that_follows_another_actors_speed_ends_at_that_speed():
    """Whether such a step ended reads its live setting (`speed(ego)`), which used to build
    the step states again: RecursionError. It ends when the follower reaches the ego's speed;
    in a sequence, and with two actors following each other, the run completes."""
    tr = run("""agent a car on r lane -1 at 40 m speed 8 m/s {
  go: at 1 s behavior cruise speed speed(ego) + 2 m/s decel 3 m/s^2
}
agent b car on r lane -3 at 40 m speed 6 m/s {
  sequence {
    wait: at 0.5 s behavior cruise speed 6 m/s
    follow: after 0.5 s behavior cruise speed speed(a)
  }
  after_a: when ended(a.go) then behavior cruise speed 3 m/s
}""")
    ended = first(tr, "a.go", STEP_ENDED)
    assert ended is not None
    # The ego holds 0 m/s (cruise_speed 0): `a` slows from 8 m/s to 2 m/s at 3 m/s^2 from 1 s: 2 s.
    assert ended * tr.period_s == pytest.approx(3.0, abs=0.05)
    assert tr.actors["a"].speed[ended] == pytest.approx(2.0, abs=0.05)
    assert first(tr, "b.after_a", STEP_STARTED) == ended


def test_an_agent_with_a_live_behaviour_still_runs_its_steps():
    """An agent whose behaviour follows another actor (`cruise speed speed(ego) + 3 m/s`)
    had its steps dropped: `go` never started and it never braked."""
    tr = run("""agent a car on r lane -1 at 40 m speed 8 m/s {
  behavior cruise speed speed(ego) + 3 m/s
  go: at 1 s behavior brake decel 4 m/s^2 to_speed 2 m/s
}""", duration=5.0)
    assert first(tr, "a.go", STEP_STARTED) == round(1.0 / tr.period_s)
    assert tr.actors["a"].speed[-1] == pytest.approx(2.0, abs=1e-3)
