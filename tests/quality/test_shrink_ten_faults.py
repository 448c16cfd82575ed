"""Quality: ten injected faults, exactly one causes the failure; shrinking finds it.

The bar: the scenario shrinks to that one fault within 150 simulations, the
written `.addt` file replays the failure with `addtc` (exit 1), and the same input
shrinks to the same result. Two culprits: a stuck acceleration command (collision with
the lead) and a stuck steering command (lane departure to the left).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from addt_dsl.cli import main as addtc
from addt_dsl.compiler import compile_source
from addt_dsl.search import RunCache, Shrinker, evaluate
from addt_dsl.search.artifacts import write_counterexample
from addt_dsl.sweep import expand

ROOT = Path(__file__).resolve().parents[2]
SOURCE = (ROOT / "examples" / "ten_faults.addt").read_text()
ACCEL_CULPRIT = "from 1 s stuck control.accel value 3"
MAX_SIMULATIONS = 150

CASES = {
    "stuck_accel": (ACCEL_CULPRIT, ("stuck", "control.accel"), "no_collision", "[with lead]"),
    "stuck_steer": ("during [2 s, 2.5 s] stuck control.steer value 0.2", ("stuck", "control.steer"),
                    "lane_keeping", "[left]"),
}

pytestmark = pytest.mark.slow


def _spec(case: str):
    culprit = CASES[case][0]
    assert ACCEL_CULPRIT in SOURCE
    result = compile_source(SOURCE.replace(ACCEL_CULPRIT, culprit), path="examples/ten_faults.addt",
                            base_dir=ROOT / "examples")
    assert result.ok, result.diagnostics
    (spec,) = expand(result.plan).specs
    return result.plan, spec


@pytest.mark.parametrize("case", sorted(CASES))
def test_ten_faults_shrink_to_the_culprit(case, tmp_path):
    plan, spec = _spec(case)
    _, culprit, oracle, mode_note = CASES[case]
    assert len(spec.faults) == 10
    culprit_index = next(i for i, f in enumerate(spec.faults) if (f.kind, f.target) == culprit)
    # The premise: all ten fail, the nine others alone pass.
    assert not evaluate(spec).passed
    nine = spec.model_copy(update={"faults": [f for i, f in enumerate(spec.faults) if i != culprit_index]})
    assert evaluate(nine).passed

    result = Shrinker(spec, nominal_plan=plan, cache=RunCache(), max_simulations=MAX_SIMULATIONS).run()
    print(f"{case}: {result.simulations} simulations, {result.cache_hits} cache hits, {result.rounds} rounds, "
          f"{result.seconds:.1f} s")
    assert [(f.kind, f.target) for f in result.best.faults] == [culprit]
    assert result.simulations <= MAX_SIMULATIONS and not result.budget_exhausted
    assert result.target.oracle == oracle and result.target.mode.endswith(mode_note)
    assert sum("did not matter: fault" in c for c in result.changes) == 9

    arts = write_counterexample(result, tmp_path, "examples/ten_faults.addt")
    assert addtc([str(arts.addt), "--jobs", "1"]) == 1
    trace = np.load(arts.trace)
    assert trace["time"][-1] <= result.best.plan.duration_s + 1e-9
    assert "ego.speed" in trace.files
    assert arts.animation is not None and arts.animation.stat().st_size > 0  # GIF from addt_dsl.reporting

    again = Shrinker(spec, nominal_plan=plan, cache=RunCache(), max_simulations=MAX_SIMULATIONS).run()
    assert again.best.key() == result.best.key()
