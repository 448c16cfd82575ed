"""Fault windows opened by a condition (`when [EDGE] C [delayed D] [for W]`): the plan
they compile to, the printer's round trip, and the runtime's window against a timed one."""

from __future__ import annotations

import math
from pathlib import Path

from addt_dsl import expr as E
from addt_dsl.compiler import compile_source
from addt_dsl.diagnostics import render_text
from addt_dsl.plan import ConcreteFault, TriggerPlan
from addt_dsl.printer import compile_pinned, pin_spec, print_plan, print_spec, semantic_key
from addt_dsl.runtime.faults import FaultSchedule
from addt_dsl.sweep import expand, make_spec
from tests.unit.runtime.faults.faultkit import STEP_S, lidar_frame

MAPS = Path(__file__).resolve().parents[3] / "examples" / "maps"

SOURCE = """
scenario windows {
  duration 10 s
  road r {
    line length 500 m
    lanes right 2
  }
  param w = 2 s in [1 s, 3 s]
  param near = 20 m in [10 m, 30 m]
  ego car on r lane -1 at 40 m speed 12 m/s {
    sensor lidar
  }
  agent walker pedestrian on r lane -2 at 90 m offset -3 m {
    go: at 2 s behavior cross speed 1.5 m/s direction left
  }
  faults {
    when started(walker.go) for w drop lidar rate 50 %
    when rising distance(ego, walker) < near delayed 0.5 s delay lidar by 50 ms
    when falling speed(ego) > 5 m/s for 0 s bitflip control.steer count 2 seed 7
    at 1 s for 2 s drop lidar rate 10 %
  }
  sweep {
    grid w in [1 s, 3 s]
  }
}
"""


def _plan():
    result = compile_source(SOURCE, "windows.addt")
    assert result.ok, render_text(result.diagnostics, result.sources)
    return result.plan


def test_a_when_timing_compiles_to_a_start_that_opens_the_window():
    drop, delay, flip, timed = _plan().faults
    # The window counts from the opening: [0, W] after it, W a parameter.
    assert (drop.start_s, drop.end_s) == (E.Num(value=0.0), E.Param(name="w"))
    assert E.signals_used(drop.opens.condition) == {"started(walker.go)"}
    assert drop.opens.edge is None and drop.opens.delay_s is None and drop.opens.hold_s is None
    # No `for`: open to the end; `delayed` and the edge as a step's.
    assert delay.end_s is None and delay.opens.edge == "rising" and delay.opens.delay_s == E.Num(value=0.5)
    assert "near" in {p.name for p in E.walk(delay.opens.condition) if isinstance(p, E.Param)}
    # `for 0 s`: an instant, as `at T` is.
    assert flip.end_s == flip.start_s and flip.opens.edge == "falling"
    assert timed.opens is None and (timed.start_s, timed.end_s) == (E.Num(value=1.0), E.Num(value=3.0))


def test_a_run_spec_carries_the_start_with_the_parameters_resolved():
    plan = _plan()
    specs = expand(plan).specs
    assert [s.faults[0].end_s for s in specs] == [1.0, 3.0]
    opens = specs[0].faults[1].opens
    assert not E.params_used(opens.condition)
    assert E.Num(value=20.0) in list(E.walk(opens.condition)) and opens.delay_s == E.Num(value=0.5)


def test_the_printer_writes_when_windows_back():
    plan = _plan()
    text = print_plan(plan, keep_user_text=False)
    assert "when started(walker.go) for w drop lidar" in text
    assert "when rising distance(ego, walker) < near delayed 0.5 s delay lidar" in text
    assert "when falling speed(ego) > 5 m/s for 0 s bitflip control.steer" in text
    again = compile_source(text, "printed.addt", base_dir=MAPS)
    assert again.ok, render_text(again.diagnostics, again.sources) + "\n" + text
    assert semantic_key(again.plan) == semantic_key(plan)


def test_a_pinned_run_with_when_windows_reads_back_to_the_same_run():
    spec = expand(_plan()).specs[1]
    text = print_spec(spec)
    again = compile_pinned(text, base_dir=MAPS)
    assert semantic_key(again) == semantic_key(pin_spec(spec))
    assert [f.model_dump(exclude={"index"}) for f in again.faults] == \
        [f.model_dump(exclude={"index"}) for f in pin_spec(spec).faults]
    assert again.faults[0].opens is not None and again.faults[0].end_s == 3.0


# ---------------------------------------------------------------- runtime

def _schedule(*faults: ConcreteFault, duration_s: float = 10.0):
    events: list = []
    return FaultSchedule(list(faults), STEP_S, duration_s, events), events


def _fault(kind: str, start: float, end: float | None, opens=None, **settings) -> ConcreteFault:
    return ConcreteFault(index=0, kind=kind, target=settings.pop("target", "lidar"), start_s=start, end_s=end,
                         settings=settings, seed=11, opens=opens)


def _opener() -> TriggerPlan:
    # The condition is only a token here: the test's `holds` answers for it.
    return TriggerPlan(condition=E.Binary(op=">", left=E.Signal(name="speed(ego)"), right=E.Num(value=0.0)))


def _run_drops(sched, fire_at: float | None, until: float = 6.0) -> list[float]:
    kind = sched.kinds[0]
    dropped = []
    for k in range(int(round(until / STEP_S)) + 1):
        t = k * STEP_S
        if sched.openers:
            sched.open_windows(t, lambda c: fire_at is not None and t >= fire_at - 1e-12)
        if k % 10 == 0:  # a 10 Hz sensor
            frame, _ = kind.on_frame(lidar_frame(stamp=t), t)
            if frame is None:
                dropped.append(round(t, 9))
    return dropped


def test_an_opened_window_acts_as_the_timed_window_from_the_opening_instant():
    """Opened at 2.3 s for 1.5 s, a drop fault draws what `during [2.3 s, 3.8 s]` draws."""
    opened, events = _schedule(_fault("drop", 0.0, 1.5, _opener(), rate=0.5))
    timed, _ = _schedule(_fault("drop", 2.3, 2.3 + 1.5, rate=0.5))
    got = _run_drops(opened, 2.3)
    assert got == _run_drops(timed, None) and got
    assert min(got) >= 2.3 - 1e-9 and max(got) <= 3.8 + 1e-9
    (window,) = [e for e in events if e.kind == "fault_window"]
    assert math.isclose(window.time_s, 2.3) and math.isclose(window.detail["end_s"], 3.8)
    assert not opened.openers  # one-shot


def test_a_window_whose_condition_never_holds_never_acts():
    sched, events = _schedule(_fault("drop", 0.0, None, _opener(), rate=1.0))
    assert _run_drops(sched, None) == []
    assert not [e for e in events if e.kind in ("fault", "fault_window")]
    assert len(sched.openers) == 1


def test_bit_flips_of_an_opened_window_are_the_timed_window_s_flips():
    opened, _ = _schedule(_fault("bitflip", 0.0, 2.0, _opener(), target="control.steer", count=4))
    timed, _ = _schedule(_fault("bitflip", 3.0, 5.0, target="control.steer", count=4))
    assert len(opened.kinds[0].times) == 0
    opened.open_windows(3.0, lambda c: True)
    assert list(opened.kinds[0].times) == list(timed.kinds[0].times)
    assert all(3.0 <= t <= 5.0 for t in timed.kinds[0].times)


def test_a_make_spec_of_a_plan_without_when_windows_has_no_openers():
    plan = _plan()
    spec = make_spec(plan.model_copy(update={"faults": plan.faults[3:]}), plan.nominal_params(), 0)
    assert [f.opens for f in spec.faults] == [None]


def test_a_tensor_flip_at_the_opening_instant_is_taken_by_the_next_forward_pass():
    """`when C for 0 s bitflip perception... tensor weights`: the flip's timer is due at the
    opening itself, which the schedule wakes at once (the loop's clock phase has passed)."""
    import pytest

    torch = pytest.importorskip("torch")
    from addt_dsl.runtime.faults.tensor import tensor_sites_of

    torch.manual_seed(0)
    model = torch.nn.Sequential(torch.nn.Linear(4, 3)).eval()
    sites = tensor_sites_of(model, "perception")
    target = sorted(sites)[0]
    sched, events = _schedule(_fault("bitflip", 0.0, 0.0, _opener(), target=target, count=1, tensor="weights",
                                     field="any", bit=-1.0))
    now = [0.0]
    stack = type("Stack", (), {"nodes": {}, "tensor_sites": lambda self: sites})()
    sched.bind(stack, lambda: now[0])
    before = [p.detach().clone() for p in model.parameters()]
    x = torch.ones(1, 4)
    model(x)  # not opened: no hook, nothing flipped
    assert all(torch.equal(a, b) for a, b in zip(before, model.parameters()))
    now[0] = 1.5
    sched.open_windows(1.5, lambda c: True)
    model(x)
    flips = [e for e in events if e.kind == "fault"]
    assert len(flips) == 1 and flips[0].time_s == 1.5
    sched.close()  # weight flips are undone
    assert all(torch.equal(a, b) for a, b in zip(before, model.parameters()))
