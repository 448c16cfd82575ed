"""benchmarks/run_all.py: every benchmark script is in its table and writes --json figures;
the headline compares figures with their targets."""

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[3] / "benchmarks"


@pytest.fixture(scope="module")
def run_all():
    sys.path.insert(0, str(BENCH))
    spec = importlib.util.spec_from_file_location("run_all", BENCH / "run_all.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_every_benchmark_script_is_run(run_all):
    scripts = {p.stem.removeprefix("bench_") for p in BENCH.glob("bench_*.py")}
    assert set(run_all.BENCHMARKS) == scripts
    for name in scripts:  # and each takes --json
        assert "--json" in (BENCH / f"bench_{name}.py").read_text(), name


def test_headline_ratios_and_verdicts(run_all):
    results = {name: {} for name in run_all.BENCHMARKS}
    results["stack"] = {"figures": {"rtf": {"ground_truth": 120.0, "learned": 60.0}}}
    results["table1"] = {"figures": {"wall_s": 480.0, "limit_per_file": None}}
    results["faults"] = {"figures": {"overhead": {"drop": 0.01, "random_value": 0.09, "blur 160x120": 0.5}}}
    rows = run_all.headline(results)
    assert rows["rtf_overtake_gt"]["met"] and rows["rtf_overtake_gt"]["ratio"] == pytest.approx(1.2)
    assert not rows["rtf_overtake_learned"]["met"]
    assert rows["table1_wall_s"]["met"] and rows["table1_wall_s"]["ratio"] == pytest.approx(0.8)
    # Camera corruptions are measured against rendering, not the run: not in the worst-kind row.
    worst = rows["fault_overhead_worst_kind"]
    assert worst["value"] == 0.09 and "random_value" in worst["unit"]
    assert "compile_1000_files_wall_s" not in rows  # not measured: no row, never a made-up one


def test_run_all_writes_one_json_file(tmp_path):
    out = tmp_path / "figures.json"
    proc = subprocess.run([sys.executable, str(BENCH / "run_all.py"), "--quick", "--only", "stl", "--out", str(out)],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    import json

    doc = json.loads(out.read_text())
    stl = doc["benchmarks"]["stl"]
    assert stl["exit_code"] == 0 and stl["figures"]["per_formula"] and len(stl["load_before"]) == 3
    assert (tmp_path / "figures-logs" / "stl.txt").exists()
