"""Documented input limits and the sweep's cost estimate (docs/limits.md).

Each limit is enforced by E0701 naming it and how to raise it (the limits are lowered
here so the inputs stay small); the estimate refuses absurd-but-compiling scenarios unless
`allow_large`; sweeps are generated lazily and sampled in bounded batches."""

from __future__ import annotations

import time
import tracemalloc
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from addt_dsl import cost
from addt_dsl import sweep as S
from addt_dsl.cli import build_parser, main
from addt_dsl.compiler import compile_file, compile_source
from addt_dsl.limits import COST_LIMITS, DEFAULT, INPUT_LIMITS, parse_limit

TIME_BOUND_S = 60.0  # generous for a loaded CI machine; idle, each case takes a second or two

SCENARIO = """scenario s {{
  duration {duration}
  step {step}
  road r {{
    line length 2000 m
    lanes right 2 width 3.5 m
  }}
{body}
  ego car on r lane -1 at 20 m speed 10 m/s
}}
"""


def scenario(body: str = "", duration: str = "10 s", step: str = "10 ms") -> str:
    return SCENARIO.format(body=body, duration=duration, step=step)


def e0701(result, name: str):
    found = [d for d in result.diagnostics if d.code == "E0701" and f"limit {name} " in d.message]
    assert found, [str(d.message) for d in result.diagnostics]
    assert not result.ok
    assert f"{name}=N" in found[0].notes[-1]  # the help line says how to raise it
    return found[0]


@pytest.mark.parametrize("name, body, line", [
    ("agents", "\n".join(f"  agent a{i} car on r lane -2 at {50 + 10 * i} m" for i in range(4)), 11),
    ("params", "\n".join(f"  param p{i} = 1 in [0, 2]" for i in range(4)), 11),
    ("oracles", "  expect {\n" + "\n".join(f"    o{i}: always speed(ego) < {50 + i} m/s" for i in range(4))
     + "\n  }", 12),
    ("faults", "  faults {\n" + "\n".join(f"    at {i + 1} s for 1 s drop lidar rate 50 %" for i in range(4))
     + "\n  }", 12),
])
def test_count_limits_name_the_limit_at_the_first_item_beyond(name, body, line):
    result = compile_source(scenario(body), "s.addt", limits=DEFAULT.raised(**{name: 3}))
    d = e0701(result, name)
    assert d.span.line == line
    assert compile_source(scenario(body), "s.addt", limits=DEFAULT.raised(**{name: 4})).ok or name == "params"


def test_roads_per_map_are_counted_before_any_is_built(tmp_path):
    road = ('<road length="100" id="{i}" junction="-1"><planView><geometry s="0" x="0" y="{y}" hdg="0" '
            'length="100"><line/></geometry></planView><lanes><laneSection s="0"><center><lane id="0"/></center>'
            '<right><lane id="-1" type="driving"><width sOffset="0" a="3.5" b="0" c="0" d="0"/></lane></right>'
            '</laneSection></lanes></road>')
    roads = "".join(road.format(i=i + 1, y=10 * i) for i in range(5))
    (tmp_path / "m.xodr").write_text(f'<?xml version="1.0"?><OpenDRIVE><header revMajor="1" revMinor="4"/>'
                                     f'<!-- <road id="99"> in a comment is not counted -->{roads}</OpenDRIVE>')
    src = tmp_path / "s.addt"
    src.write_text('scenario s {\n  duration 10 s\n  road r import "m.xodr"\n  ego car on r lane -1 at 20 m\n}\n')
    assert compile_file(src, DEFAULT.raised(roads_per_map=5)).ok
    d = e0701(compile_file(src, DEFAULT.raised(roads_per_map=4)), "roads_per_map")
    assert (d.span.line, d.span.col) == (3, 3) and str(tmp_path) not in d.message


def test_included_bytes_count_every_include(tmp_path):
    for k in range(3):
        (tmp_path / f"lib{k}.addt").write_text(f"param q{k} = 1 m in [0 m, 2 m]\n" + "#" * 1000 + "\n")
    src = tmp_path / "s.addt"
    src.write_text("".join(f'include "lib{k}.addt"\n' for k in range(3)) + scenario())
    assert compile_file(src).ok
    d = e0701(compile_file(src, DEFAULT.raised(included_bytes=2500)), "included_bytes")
    assert d.span.line == 3  # the third include passes the total


def test_a_main_file_beyond_source_bytes_says_how_to_raise_it(tmp_path):
    src = tmp_path / "s.addt"
    src.write_text(scenario())
    (d,) = compile_file(src, DEFAULT.raised(source_bytes=100)).diagnostics
    assert d.code == "E0003" and "source_bytes" in d.message and "--max source_bytes=N" in d.notes[-1]
    assert compile_file(src, DEFAULT.raised(source_bytes=len(src.read_bytes()))).ok


def test_the_estimate_follows_the_documented_model():
    result = compile_source(scenario("  agent a car on r lane -2 at 60 m\n  sweep {\n    repeat 3\n  }",
                                     duration="20 s", step="50 ms"))
    est = result.estimate
    assert (est.runs, est.runs_exact, est.samples_per_run, est.actors) == (3, True, 401, 2)
    assert est.agent_steps_per_run == 802 and est.agent_steps == 3 * 802 and est.sim_seconds == 60
    assert est.lidar_rays_per_run == 360 * 5 * 10.0 * 20  # the ego's default lidar: 5 channels
    assert est.run_memory_bytes == cost.RUN_BASE_BYTES + 401 * 8 * (1 + cost.TRACE_FIELDS * 2 + cost.LATENCY_SERIES)


def test_absurd_but_compiling_scenarios_are_refused_by_the_estimate():
    plan = compile_source(scenario("  agent a car on r lane -2 at 60 m")).plan
    crowd = plan.model_copy(update={"agents": plan.agents * 100_000})  # 100,000 agents
    names = [n for n, _ in cost.over_thresholds(cost.estimate(crowd), DEFAULT)]
    assert "agent_steps_per_run" in names and "run_memory_bytes" in names
    assert cost.over_thresholds(cost.estimate(crowd), DEFAULT.raised(allow_large=True)) == []
    # 50 agents for 3,600 s at 1 ms: about 16 GB of trace per run
    long = plan.model_copy(update={"agents": plan.agents * 50, "duration_s": 3600.0, "step_s": 0.001})
    assert cost.estimate(long).run_memory_bytes > 16e9


def test_allow_large_and_max_lift_a_cost_threshold():
    src = scenario("  param p = 1 m in [0 m, 2 m]\n  assume p > 0.5 m\n"
                   "  sweep {\n    random 1000000\n    repeat 2\n  }", duration="1 s")
    e0701(compile_source(src), "runs")
    assert compile_source(src, limits=DEFAULT.raised(allow_large=True)).ok
    # 2e6 runs of about 0.07 s are also beyond wall_seconds (1e5 s): each threshold is raised by name.
    e0701(compile_source(src, limits=parse_limit("runs=2e6")), "wall_seconds")
    assert compile_source(src, limits=parse_limit("wall_seconds=1e6", parse_limit("runs=2e6"))).ok
    assert compile_source(src, limits=DEFAULT.raised(run_cap=10)).ok  # `addtc FILE --limit 10`


def test_a_huge_grid_is_counted_and_streamed_not_built():
    axes = "\n".join(f"  param p{i} = 1 m in [0 m, 9 m]" for i in range(12))
    grid = "\n".join(f"    grid p{i} in [0, 1, 2, 3, 4, 5, 6, 7, 8, 9] m" for i in range(12))
    used = " + ".join(f"p{i}" for i in range(12))
    src = scenario(f"{axes}\n  agent a car on r lane -2 at 30 m + {used}\n  sweep {{\n{grid}\n  }}")
    t0 = time.monotonic()
    e0701(compile_source(src), "runs")
    result = compile_source(src, limits=DEFAULT.raised(allow_large=True))
    assert result.ok and result.estimate.runs == 10 ** 12
    stream = S.SweepStream(result.plan)
    assert len(stream) == 10 ** 12
    first = next(iter(stream))
    assert first.cell == {f"p{i}": 0.0 for i in range(12)}
    assert time.monotonic() - t0 < TIME_BOUND_S


def test_lhs_over_many_params_is_drawn_in_bounded_batches():
    n = 1000  # 1e6 samples of 1,000 parameters: 8 GB if drawn at once
    params = "\n".join(f"  param p{i} = 1 m in [0 m, 2 m]" for i in range(n))
    src = scenario(f"{params}\n  sweep {{\n    lhs 1000000\n  }}")  # unused params: warnings only
    t0 = time.monotonic()
    result = compile_source(src, limits=DEFAULT.raised(allow_large=True))
    assert result.ok, [d.message for d in result.diagnostics if d.is_error]
    tracemalloc.start()
    try:
        spec = next(iter(S.SweepStream(result.plan)))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert len(spec.params) == n
    assert peak < 200e6  # one batch of SAMPLE_BATCH_VALUES numbers
    assert time.monotonic() - t0 < TIME_BOUND_S


def test_batching_does_not_change_random_samples(monkeypatch):
    src = scenario("  param p = 1 m in [0 m, 2 m]\n  param q = 1 m in [0 m, 2 m]\n"
                   "  agent a car on r lane -2 at 40 m + p + q\n  sweep {\n    random 9\n  }")
    plan = compile_source(src).plan
    whole = [s.params for s in S.expand(plan).specs]
    monkeypatch.setattr(S, "SAMPLE_BATCH_VALUES", 4)  # two samples of two parameters per batch
    assert [s.params for s in S.expand(plan).specs] == whole


def test_every_limit_has_a_documented_name_and_parses():
    text = (Path(__file__).resolve().parents[3] / "docs" / "limits.md").read_text()
    for name in (*INPUT_LIMITS, *COST_LIMITS):
        assert f"`{name}`" in text, name
        assert getattr(parse_limit(f"{name}=7"), name) == 7
    with pytest.raises(ValueError, match="NAME one of"):
        parse_limit("lanes=3")
    with pytest.raises(ValueError, match="finite"):
        parse_limit("runs=inf")


def test_check_prints_the_estimate_and_takes_the_options(tmp_path, capsys):
    src = tmp_path / "s.addt"
    src.write_text(scenario("  param p = 1 m in [0 m, 2 m]\n  agent a car on r lane -2 at 40 m + p\n"
                            "  sweep {\n    random 1000000\n    repeat 2\n  }", duration="1 s"))
    assert main(["check", str(src)]) == 2
    assert "E0701" in capsys.readouterr().err
    assert main(["check", "--allow-large", str(src)]) == 0
    out = capsys.readouterr().out
    assert "cost estimate: 2,000,000 run(s) x 1 s" in out and "actor-steps" in out and "MiB" in out
    assert main(["plan", "--max", "runs=3000000", "--max", "wall_seconds=1e6", str(src)]) == 0
    assert "cost estimate" in capsys.readouterr().err
    assert main(["check", "--max", "bogus=1", str(src)]) == 2
    assert build_parser().parse_args(["run", "--allow-large", "--max", "agents=5", "x.addt"]).max == ["agents=5"]


def test_a_limit_raised_very_high_reads_only_what_is_there(tmp_path):
    src = tmp_path / "s.addt"
    src.write_text(scenario())
    huge = DEFAULT.raised(source_bytes=10 ** 12, included_bytes=10 ** 12, read_bytes=10 ** 12, map_bytes=10 ** 12)
    assert compile_file(src, huge).ok  # no terabyte buffer allocated for the read


EXAMPLE_FILES = sorted((Path(__file__).resolve().parents[3] / "examples").rglob("*.addt"))


@settings(max_examples=40, deadline=None)
@given(st.sampled_from(EXAMPLE_FILES), st.sampled_from((*INPUT_LIMITS, *COST_LIMITS)), st.integers(0, 50))
def test_any_lowered_limit_is_a_named_diagnostic_never_an_internal_error(path, name, value):
    result = compile_file(path, DEFAULT.raised(**{name: value}))
    assert "E0900" not in {d.code for d in result.diagnostics}
    for d in result.diagnostics:
        if d.code == "E0701":
            assert " is beyond the limit " in d.message and "=N" in d.notes[-1]


def test_camera_pixels_are_estimated_and_bounded():
    cams = ("    sensor lidar\n    sensor camera width 320 height 240 rate 10 Hz\n"
            "    sensor camera_rig cameras 6 width 128 height 40 rate 10 Hz\n")
    src = scenario(duration="20 s").replace("speed 10 m/s\n", "speed 10 m/s {\n" + cams + "  }\n", 1)
    result = compile_source(src)
    assert result.ok, [str(d) for d in result.diagnostics]
    est = result.estimate
    assert est.camera_pixels_per_run == (320 * 240 + 6 * 128 * 40) * 10.0 * 20
    assert "camera pixels" in est.lines()[1]
    big = src.replace("width 320 height 240 rate 10 Hz", "width 1920 height 1080 rate 30 Hz").replace("20 s", "600 s")
    e0701(compile_source(big), "camera_pixels_per_run")
    # 3.75e10 pixels also take about 5 h (run_wall_seconds, 3600 s): each threshold is raised by name.
    e0701(compile_source(big, limits=parse_limit("camera_pixels_per_run=1e11")), "run_wall_seconds")
    assert compile_source(big, limits=parse_limit("run_wall_seconds=1e5", parse_limit("camera_pixels_per_run=1e11"))).ok
    assert "camera pixels" not in compile_source(scenario()).estimate.lines()[1]  # none without a camera
