"""`addtc study` hands its runs to the executors in batches (`--batch`, the run functions'
`run_batch`): its tables are the same whether each worker steps 1 or 4 runs together, on
one job and on two workers. The runs are faulty (frame drops), so `classify` compares
each with its golden twin and `perception` matches detections."""

from __future__ import annotations

import pytest

from addt_dsl import studies
from addt_dsl.runtime import executor
from addt_dsl.runtime.executor import execute_batch, run_batch, run_spec
from addt_dsl.compiler import compile_source
from addt_dsl.sweep import expand

SCENARIO = """scenario ccrs_batches {
  duration 2 s
  road r {
    line length 300 m
    lanes right 1 width 3.5 m
  }
  param gap = 15 m in [5 m, 100 m]
  ego car on r lane -1 at 20 m speed 20 m/s {
    stack bev cruise_speed 20 m/s
    sensor lidar rate 10 Hz rays 90 range 80 m
  }
  agent target car on r lane -1 at 24.6 m + gap speed 0 m/s
  faults {
    drop lidar rate 30 %
  }
  expect {
    no collision
  }
  sweep {
    grid gap in [5, 15, 30, 60] m
  }
}
"""

pytestmark = pytest.mark.slow


@pytest.mark.parametrize("what", ["impact", "perception", "classify"])
def test_study_tables_are_the_same_at_any_batch(what, tmp_path, capsys, monkeypatch):
    path = tmp_path / "ccrs.addt"
    path.write_text(SCENARIO)
    sizes = []  # batches stepped in this process (one job)

    def spy(specs, keep_trace=True):
        sizes.append(len(specs))
        return execute_batch(specs, keep_trace)

    monkeypatch.setattr(executor, "execute_batch", spy)
    tables = []
    for batch, jobs in ((1, 1), (4, 1), (2, 2)):
        assert studies.main([what, str(path), "--by", "gap", "--batch", str(batch), "--jobs", str(jobs)]) == 0
        tables.append(capsys.readouterr().out)
        if jobs == 1:
            assert max(sizes, default=1) == batch, (batch, sizes)
    assert tables[0].count("\n") >= 4, tables[0]
    assert tables[1] == tables[0] and tables[2] == tables[0]


def test_a_batch_records_what_each_run_alone_records():
    plan = compile_source(SCENARIO.encode(), path="ccrs.addt").plan
    specs = expand(plan).specs
    for run_fn in (studies.impact_run, studies.perception_run):
        alone = [run_fn(s, i) for i, s in enumerate(specs)]
        together = run_fn.run_batch(specs, list(range(len(specs))))
        assert [(r.digest, r.stats) for r in together] == [(r.digest, r.stats) for r in alone]
        assert len({r.digest for r in together}) == len(specs)  # four different runs


def test_a_run_whose_summary_raises_is_crashed_alone_in_its_batch():
    plan = compile_source(SCENARIO.encode(), path="ccrs.addt").plan
    specs = expand(plan).specs[:2]

    def fussy(result):
        if result.params["gap"] == 5.0:
            raise ValueError("no summary for this one")

    batch = run_batch(specs, [0, 1], on_result=fussy)
    alone = [run_spec(s, i, on_result=fussy) for i, s in enumerate(specs)]
    assert [r.status for r in batch] == [r.status for r in alone] == ["crashed", "ok"]
    assert "no summary for this one" in batch[0].error
