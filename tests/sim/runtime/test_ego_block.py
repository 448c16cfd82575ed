"""The egos of a batch in one block of states (`vehicle.StateBlock`): a scripted ego, a
stack-driven ego on a 20 ms step (two substeps), one on a route (a networked run) and one on
a plain road, batched in either order, give their traces alone bit for bit; the driven egos
step in one kernel call per sample, and the block and each run's `VehicleState` agree."""

from __future__ import annotations

import numpy as np

from addt_dsl.compiler import compile_source
from addt_dsl.runtime import vehicle
from addt_dsl.runtime.execute import execute, execute_batch
from addt_dsl.sweep import expand
from tests.sim.runtime.test_batch import EXAMPLES, full_digest
from tests.sim.runtime.test_scripted_ego import CRUISE


def _spec(source: str, name: str):
    result = compile_source(source, name, base_dir=EXAMPLES)
    assert result.ok, [str(d) for d in result.diagnostics]
    return expand(result.plan).specs[0]


def _specs():
    def example(name: str, duration: str):
        return _spec((EXAMPLES / name).read_text().replace(duration, "duration 3 s"), name)

    return [_spec(CRUISE % "", "scripted.addt"), example("lead_brake.addt", "duration 9 s"),
            example("ramp_merge.addt", "duration 14 s"), example("overtake.addt", "duration 30 s")]


def test_mixed_egos_batched_are_alone(monkeypatch):
    specs = _specs()
    assert [s.plan.step_s for s in specs] == [0.01, 0.02, 0.01, 0.01]
    alone = [full_digest(execute(s)) for s in specs]
    calls = []
    step = vehicle.StateBlock.step

    def counted(self, inputs, params, rows):
        calls.append(len(inputs))
        return step(self, inputs, params, rows)

    monkeypatch.setattr(vehicle.StateBlock, "step", counted)
    for order in ([0, 1, 2, 3], [3, 2, 1, 0]):
        calls.clear()
        got = dict(zip(order, (full_digest(r) for r in execute_batch([specs[i] for i in order]))))
        assert [got[i] for i in range(len(specs))] == alone, order
        assert max(calls) == 3  # the three driven egos in one call (the scripted one moves as agents do)
    assert len(calls) == 500  # one call a sample (the longest run: 5 s of 10 ms)


def test_block_and_states_agree_in_the_loop(monkeypatch):
    """At every ego phase the block's rows are the runs' states read by attribute."""
    from addt_dsl.runtime import phases

    checked = []
    ego = phases.ego

    def checking(runs, ts, egos):
        out = ego(runs, ts, egos)
        for run in runs:
            assert np.shares_memory(run.ego.row, egos.states)
            assert egos.states[run.ego_row].tolist() == [getattr(run.ego, f) for f in vehicle.STATE_FIELDS]
        checked.append(len(runs))
        return out

    monkeypatch.setattr(phases, "ego", checking)
    execute_batch(_specs()[:3])
    assert max(checked) == 3
