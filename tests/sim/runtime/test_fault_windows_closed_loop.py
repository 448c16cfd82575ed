"""Closed loop: a lidar drop window that opens when a named step starts.

Hand calculation of the opening instant: the lead is an agent at a constant 10 m/s from
s = 20 m, so at sample k (t = k * 10 ms) it is at s = 20 m + 0.1 m * k. Its step
`go: when s(lead) >= 50.05 m` fires at the first recorded sample where that holds:
k = 301, t_fire = 3.01 s (k = 300 is at 50.0 m). The fault `when started(lead.go) for
0.95 s` opens at the sample where the trace first records the step as started, 3.01 s,
and acts in [3.01 s, 3.96 s] (closed, as `at T for D`). The lidar captures every 0.1 s,
so with `rate 100 %` the frames of 3.1 s ... 3.9 s are lost, 9 frames, and no other.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from addt_dsl.compiler import compile_source
from addt_dsl.reporting.trace_view import unopened_windows
from addt_dsl.runtime.execute import execute
from addt_dsl.sweep import expand

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[3]

TEMPLATE = """
scenario opened {{
  duration 6 s
  road r {{
    line length 600 m
    lanes right 2
  }}
  ego car on r lane -1 at 10 m speed 10 m/s {{
    stack bev cruise_speed 10 m/s
    sensor lidar rate 10 Hz
  }}
  agent lead car on r lane -2 at 20 m speed 10 m/s {{
    behavior cruise speed 10 m/s
    go: when s(lead) >= {threshold} then behavior cruise speed 12 m/s
  }}
  faults {{
    {fault} drop lidar rate {rate} seed 5
  }}
}}
"""

OPENED = "when started(lead.go) for 0.95 s"


def _spec(threshold: str = "50.05 m", fault: str = OPENED, rate: str = "100 %"):
    source = TEMPLATE.format(threshold=threshold, fault=fault, rate=rate)
    result = compile_source(source, "opened.addt")
    assert result.ok, [str(d) for d in result.diagnostics]
    return expand(result.plan).specs[0]


def _run(*a, **kw):
    return execute(_spec(*a, **kw))


def _drops(result) -> list[float]:
    return [round(e.time_s, 6) for e in result.trace.events if e.kind == "fault"]


def test_frames_are_dropped_exactly_in_the_window_the_step_opens():
    result = _run()
    (fired,) = [e.time_s for e in result.trace.events if e.kind == "trigger" and e.detail.get("actor") == "lead"
                and e.detail["behavior"] == "cruise" and e.time_s > 0]
    assert fired == pytest.approx(3.01, abs=1e-9)  # k = 301, by hand
    (window,) = [e for e in result.trace.events if e.kind == "fault_window"]
    assert window.time_s == pytest.approx(3.01, abs=1e-9)
    assert window.detail["start_s"] == pytest.approx(3.01) and window.detail["end_s"] == pytest.approx(3.96)
    assert _drops(result) == [round(3.1 + 0.1 * i, 6) for i in range(9)]
    # The trace's own record of the step: started from the window's first sample on.
    started = result.trace.steps["lead.go"]
    k_first = int(next(i for i, code in enumerate(started) if code != 0))
    assert k_first == 301


def test_the_opened_window_draws_what_the_timed_window_at_t_fire_draws():
    """At a 50 % rate the drops depend on the fault's random stream: the window a step opens
    at 3.01 s loses the frames the window `during [3.01 s, 3.96 s]` loses, same seed."""
    opened = _drops(_run(rate="50 %"))
    timed = _drops(_run(fault="during [3.01 s, 3.96 s]", rate="50 %"))
    assert opened == timed and 0 < len(opened) < 9


def test_without_the_step_firing_nothing_is_dropped():
    spec = _spec(threshold="500 m")  # the lead never gets there in 6 s
    result = execute(spec)
    assert not [e for e in result.trace.events if e.kind in ("fault", "fault_window")]
    assert result.fault_events == 0
    # `addtc trace` says why: the window never opened.
    (line,) = unopened_windows(spec, result.trace)
    assert line.startswith("fault 0 (drop lidar): its window never opened")
    assert unopened_windows(_spec(), _run().trace) == []


RUNNER = """
import json, sys
from addt_dsl.compiler import compile_source
from addt_dsl.reporting.trace_view import unopened_windows
from addt_dsl.runtime.execute import execute
from addt_dsl.sweep import expand
spec = expand(compile_source(sys.argv[1], "opened.addt").plan).specs[0]
r = execute(spec)
print(json.dumps([spec.key(), r.trace.digest(), sum(e.kind == "fault" for e in r.trace.events)]))
"""


def test_same_run_key_same_digest_under_other_hash_seeds():
    source = TEMPLATE.format(threshold="50.05 m", fault=OPENED, rate="50 %")
    out = []
    for seed in (0, 4242):
        env = {**os.environ, "PYTHONHASHSEED": str(seed), "PYTHONPATH": str(ROOT)}
        done = subprocess.run([sys.executable, "-c", RUNNER, source], env=env, cwd=ROOT, capture_output=True,
                              text=True, timeout=300)
        assert done.returncode == 0, done.stderr[-3000:]
        out.append(json.loads(done.stdout.strip().splitlines()[-1]))
    assert out[0] == out[1] and out[0][2] > 0
