"""Export, import the export back, run both: the same trajectories (compared sample by sample,
not the text). With the side file every actor; from the OpenSCENARIO file alone the actors
whose actions OpenSCENARIO holds (the ego's stack lives in the side file)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from addt_dsl.compiler import compile_file, compile_source
from addt_dsl.diagnostics import render_text
from addt_dsl.interop.openscenario.importer import import_xosc
from addt_dsl.interop.xosc_export import export_run
from addt_dsl.runtime.execute import execute
from addt_dsl.sweep import expand

ROOT = Path(__file__).resolve().parents[3]
ESMINI = ROOT / "tests" / "data" / "esmini"


def run(plan):
    return execute(expand(plan).specs[0]).trace


def largest_gap(a, b, names, span_s: float | None = None) -> dict[str, float]:
    """Per actor, the largest distance [m] between the two runs at the same samples (the
    whole runs, or their first `span_s` when one ends earlier)."""
    out = {}
    for n in names:
        x, y = a.actors[n], b.actors[n]
        k = len(x.x) if span_s is None else int(round(span_s / a.period_s)) + 1
        assert len(x.x) >= k and len(y.x) >= k, n
        out[n] = float(np.max(np.hypot(x.x[:k] - y.x[:k], x.y[:k] - y.y[:k])))
    return out


def back(done, tmp_path: Path, side: bool, **options):
    where = tmp_path / ("with" if side else "without")
    where.mkdir()
    for f in (done.xosc_path, done.xodr_path) + ((done.sidecar_path,) if side else ()):
        (where / f.name).write_bytes(f.read_bytes())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        got = import_xosc(where / done.xosc_path.name, **options)
    assert got.plan is not None, [d.message for d in got.diagnostics]
    # (the printed text compiles to the plan that runs: the printer's round trip too)
    again = compile_source(got.text, "back.addt", base_dir=where)
    assert again.ok, render_text(again.diagnostics, again.sources)
    return again.plan


@pytest.mark.parametrize("side", [True, False])
def test_road_ends_teleports_and_repeats_run_back_the_same(side, tmp_path):
    plan = compile_file(ROOT / "tests" / "data" / "interop" / "every_road_end.addt").plan
    done = export_run(expand(plan).specs[0], tmp_path / "out", "every_road_end")
    first = run(plan)
    looper = first.actors["looper"]
    assert np.any(np.diff(looper.s) < -40.0)  # (it was put back: the run exercises the teleport)
    assert np.ptp(first.actors["follower"].t) > 3.0  # (its headway and acceleration conditions fired)
    # From the OpenSCENARIO file alone the ego is the stack's own (its settings are in the side
    # file): it drives off and the run ends at its first collision, 5.2 s; up to then, the same.
    gaps = largest_gap(first, run(back(done, tmp_path, side)), ["ego"] * side + ["looper", "follower"],
                       None if side else 5.1)
    assert max(gaps.values()) < 1e-9, gaps


@pytest.mark.parametrize("side", [True, False])
def test_imported_cut_in_simple_exports_and_runs_back_the_same(side, tmp_path):
    # Its headway conditions carry a parameter (`gap(ego, OverTaker) > HeadwayTime_Brake *
    # speed(ego)`): once the export could not write them (no dimension for the parameter).
    got = import_xosc(ESMINI / "xosc" / "cut-in_simple.xosc", root=ESMINI)
    src = tmp_path / "src"
    src.mkdir()
    for file, body in got.side_files.items():
        (src / file).write_text(body)
    first = compile_source(got.text, "cut_in_simple.addt", base_dir=src)
    assert first.ok, render_text(first.diagnostics, first.sources)
    done = export_run(expand(first.plan).specs[0], tmp_path / "out", "cut_in_simple")
    text = done.xosc_path.read_text()
    assert text.count("<TimeHeadwayCondition") == 2 and "<AccelerationCondition" in text  # not placeholders
    one, two = run(first.plan), run(back(done, tmp_path, side))
    assert np.ptp(one.actors["OverTaker"].t) > 3.0  # (it cut in: the headway conditions fired)
    gaps = largest_gap(one, two, ["ego", "OverTaker"])
    assert max(gaps.values()) < 1e-9, gaps
