"""A run's plot shows when each fault acted and each light's state; the trace's CSV has a
`light(C)` column per controller (state codes of `plan.LIGHT_STATES`)."""

from __future__ import annotations

import numpy as np
import pandas as pd

from addt_dsl import cli
from addt_dsl.compiler import compile_source
from addt_dsl.errors import EXIT_OK
from addt_dsl.plan import LIGHT_STATES
from addt_dsl.reporting.plots import fault_injections, signals_figure
from addt_dsl.reporting.trace_view import events_table, signals_table
from addt_dsl.runtime.execute import execute
from addt_dsl.sweep import expand

SRC = """
scenario lf {
  duration 4 s
  road r {
    line length 200 m
    lanes right 2
  }
  lights {
    signal s1 road r at 120 m lane -1
    controller main signals [s1] green 1 s yellow 1 s red 5 s
  }
  ego car on r lane -1 at 10 m speed 10 m/s {
    stack bev cruise_speed 10 m/s
  }
  faults {
    during [1 s, 2 s] bitflip control.steer count 3 field exponent seed 11
    at 2.5 s stuck control.accel value -2
  }
}
"""


def _run():
    spec = expand(compile_source(SRC, "lf.addt").plan).specs[0]
    result = execute(spec, keep_trace=True)
    return spec, result, signals_table(spec, result.trace), events_table(result.trace)


def test_light_states_are_columns_and_the_plot_shows_them_and_the_faults():
    spec, result, table, events = _run()
    t = table["time_s"].to_numpy()
    light = table["light(main)"].to_numpy()
    # The program: green for 1 s, yellow for 1 s, then red (hand-computed from the scenario).
    assert (light[t < 0.99] == LIGHT_STATES["green"]).all()
    assert (light[(t > 1.01) & (t < 1.99)] == LIGHT_STATES["yellow"]).all()
    assert (light[t > 2.01] == LIGHT_STATES["red"]).all()
    faults = fault_injections(events)
    assert list(faults) == ["#0 bitflip control.steer", "#1 stuck control.accel"]
    flips = faults["#0 bitflip control.steer"]
    assert len(flips) == 3 and all(1.0 <= x <= 2.0 for x in flips)
    assert faults["#1 stuck control.accel"][0] == np.float64(2.5)
    fig = signals_figure(table, result.verdicts, events)
    by_label = {ax.get_ylabel(): ax for ax in fig.axes}
    assert "lights" in by_label and "faults\ninjected" in by_label
    ticks = by_label["faults\ninjected"]
    drawn = [sorted(float(seg[0][0]) for seg in c.get_segments()) for c in ticks.collections]
    assert drawn == [sorted(flips), [2.5]]
    assert [x.get_text() for x in by_label["lights"].get_yticklabels()] == ["main"]
    # Each state is a band of its colour over the times the light shows it.
    assert len(by_label["lights"].collections) == len(LIGHT_STATES)


def test_trace_csv_has_the_light_column(tmp_path):
    source = tmp_path / "lf.addt"
    source.write_text(SRC)
    assert cli.main([str(source), "--out", str(tmp_path / "out"), "--no-report"]) in (EXIT_OK, 1)
    csv = tmp_path / "c.csv"
    assert cli.main(["trace", str(tmp_path / "out"), "c000-r000", "--csv", str(csv)]) == EXIT_OK
    table = pd.read_csv(csv)
    assert set(table["light(main)"]) == {0.0, 1.0, 2.0}
