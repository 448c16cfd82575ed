"""A counterexample written by shrink (and falsify, and the pytest plugin: one writer) comes
with its replay's ground truth as an OSI trace (`S.osi`) that OSI's reader reads back with
the replay's poses; without the `osi` extra the listing says why there is none."""

from __future__ import annotations

import numpy as np
import pytest

from addt_dsl import extras
from addt_dsl.compiler import compile_source
from addt_dsl.search import RunCache, Shrinker
from addt_dsl.search.artifacts import write_counterexample
from addt_dsl.search.commands import print_shrink_summary
from addt_dsl.sweep import expand

SRC = """
scenario fast {
  duration 2 s
  road r {
    line length 300 m
    lanes right 2
  }
  ego car on r lane -1 at 10 m speed 10 m/s {
    stack bev cruise_speed 10 m/s
  }
  agent lead car on r lane -1 at 40 m speed 8 m/s
  expect {
    slow: always speed(ego) < 5 m/s
  }
}
"""


def _shrunk():
    plan = compile_source(SRC, "fast.addt").plan
    return Shrinker(expand(plan).specs[0], nominal_plan=plan, cache=RunCache(), max_simulations=2).run()


def test_a_counterexample_has_an_osi_trace_of_its_replay(tmp_path):
    pytest.importorskip("osi3", reason="the `osi` extra (osi-python) is not installed")
    from osi3trace.osi_trace import OSITrace

    arts = write_counterexample(_shrunk(), tmp_path, "fast.addt", animate=False)
    assert arts.osi == tmp_path / f"{arts.addt.stem}.osi" and arts.osi in arts.files and not arts.osi_note
    arrays = np.load(arts.trace)
    reader = OSITrace(str(arts.osi), "SensorView")
    messages = list(reader)
    reader.close()
    assert len(messages) == len(arrays["time"])
    for k in (0, len(messages) // 2, len(messages) - 1):
        objects = messages[k].global_ground_truth.moving_object
        for name, o in zip(("ego", "lead"), objects):
            assert (o.base.position.x, o.base.position.y) == (arrays[f"{name}.x"][k], arrays[f"{name}.y"][k])


def test_without_the_osi_extra_the_listing_says_why(tmp_path, monkeypatch, capsys):
    real = extras.missing
    monkeypatch.setattr(extras, "missing", lambda module: module == "osi3" or real(module))
    result = _shrunk()
    arts = write_counterexample(result, tmp_path, "fast.addt", animate=False)
    assert arts.osi is None and not list(tmp_path.glob("*.osi"))
    assert "the `osi` extra" in arts.osi_note
    print_shrink_summary(result, arts)
    out = capsys.readouterr().out
    assert "no OSI trace: an OSI trace" in out and "pip install" in out
