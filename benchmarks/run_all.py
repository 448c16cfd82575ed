"""Run every benchmark and write one JSON file of figures.

Run: python benchmarks/run_all.py [--out bench-results.json] [--quick] [--only NAME ...]

Each `bench_*.py` runs in its own process (fresh imports, no shared caches) with
`--json`, and its figures land under `benchmarks.<name>` together with its exit code,
wall time and the load average before it started: the machines are shared, and a figure
without its load is not comparable. `headline` collects the figures the project sets
targets for, each with its target and ratio. `--quick` runs lighter settings (a smoke
test of the whole set; its figures are not the targets' measurements).
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import _figures as figures_json

HERE = Path(__file__).resolve().parent
REPO = HERE.parent

# name: (full arguments, quick arguments)
BENCHMARKS: dict[str, tuple[list[str], list[str]]] = {
    "road": ([], []),
    "stl": ([], []),
    "compile": (["--files", "1000"], ["--files", "100"]),
    "compile_scaling": ([], ["--quick"]),
    "twin": ([], ["--quick"]),
    "dense": ([], ["--quick"]),
    "stack": ([], ["--repeats", "1"]),
    "faults": (["--repeat", "9"], ["--repeat", "2"]),
    "runner": ([], ["--runs", "40", "--memory-runs", "500"]),
    "tables_memory": ([], ["--small", "500", "--large", "2000"]),
    "search": ([], ["--seeds", "2", "--budget", "60", "--scenarios", "examples/search/cut_in.addt"]),
    "shrink": ([], []),
    "peers": (["--runs", "5"], ["--runs", "1"]),
    "perception_gpu": (["--batches", "1", "16", "256"], ["--batches", "1", "16"]),
    "table1": ([], ["--limit", "8"]),
    "routes": ([], ["--runs", "1"]),
    "camera_bev": ([], ["--repeats", "1", "--duration", "10"]),
    "cost_model": ([], ["--quick"]),
    "batch": (["--scaling"], ["--quick"]),
    "agents_step": ([], ["--agents", "1,50", "--batches", "1,16", "--repeat", "2"]),
    "pose": ([], ["--agents", "5,50", "--batches", "1,16", "--repeat", "1"]),
    "planner": ([], ["--repeats", "20", "--rounds", "1"]),
    "collisions": ([], ["--agents", "5,50", "--batch", "1,16", "--rounds", "1"]),
    "phases": ([], ["--agents", "5,50", "--batches", "1,16", "--repeat", "1"]),
    "lidar": ([], ["--lidars", "360x5", "--cars", "1,20", "--frames", "100", "--repeat", "1"]),
    "stack_step": ([], ["--repeats", "1"]),
    "learned_frame": ([], ["--seconds", "1"]),
}


def _git_commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "HEAD"], cwd=REPO, capture_output=True, text=True,
                              check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return ""


def run_one(name: str, args: list[str], log_dir: Path) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "figures.json"
        cmd = [sys.executable, str(HERE / f"bench_{name}.py"), *args, "--json", str(out)]
        env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
        entry: dict = {"command": " ".join(["python", f"benchmarks/bench_{name}.py", *args]),
                       "load_before": figures_json.load()}
        t0 = time.perf_counter()
        proc = subprocess.run(cmd, env=env, capture_output=True, text=True, cwd=REPO)
        entry["wall_s"] = time.perf_counter() - t0
        entry["exit_code"] = proc.returncode
        (log_dir / f"{name}.txt").write_text(proc.stdout + ("\n--- stderr\n" + proc.stderr if proc.stderr else ""))
        if out.exists():
            entry["figures"] = json.loads(out.read_text())
        if proc.returncode != 0 or not out.exists():
            entry["error"] = (proc.stderr or proc.stdout)[-1500:]
        return entry


def _get(d: dict, *path, default=None):
    for key in path:
        if not isinstance(d, dict) or key not in d:
            return default
        d = d[key]
    return d


def headline(results: dict) -> dict:
    """The figures with a target: value, target, ratio (value / target)."""
    b = {name: r.get("figures", {}) for name, r in results.items()}
    rows = {}

    def row(key, value, target, better="higher", unit=""):
        if value is None:
            return
        rows[key] = {"value": value, "target": target, "unit": unit,
                     "ratio": value / target if target else None,
                     "met": (value >= target) if better == "higher" else (value <= target)}

    row("rtf_overtake_gt", _get(b["stack"], "rtf", "ground_truth"), 100.0, unit="x real time")
    row("rtf_overtake_learned", _get(b["stack"], "rtf", "learned"), 100.0, unit="x real time")
    # Every paper family, not the cheapest (the target: learned >= 150x in each).
    for family, rtf in (_get(b["stack"], "rtf_families") or {}).items():
        if isinstance(rtf, dict):
            row(f"rtf_family_{family}_learned", rtf.get("learned"), 150.0, unit="x real time (wall)")
            row(f"rtf_family_{family}_learned_cpu", rtf.get("learned_cpu"), 150.0, unit="x real time (CPU)")
    tensor = _get(b["faults"], "tensor", "ratio") or {}
    if tensor:
        row("tensor_fault_last_second_overhead", tensor["activations, last second"] - 1.0, 0.05, better="lower",
            unit=f"fraction of the run (noise floor {tensor['none (again)'] - 1.0:+.3f})")
        row("tensor_fault_in_window_overhead", tensor["activations, whole run, 1 flip/s"] - 1.0, 0.05,
            better="lower", unit="fraction, window = whole run, 1 flip/s")
    row("table1_wall_s", _get(b["table1"], "wall_s") if not _get(b["table1"], "limit_per_file") else None,
        600.0, better="lower", unit="s")
    compiled = _get(b["compile"], "examples") or {}
    row("compile_1000_suite_files_wall_s", compiled.get("wall_s") if compiled.get("files") == 1000 else None,
        2.0, better="lower", unit="s (examples suite, one core)")
    row("compile_1000_files_wall_s", _get(b["compile"], "wall_s") if _get(b["compile"], "files") == 1000 else None,
        2.0, better="lower", unit="s (generated suite, nothing shared, one core)")
    row("end_of_sweep_tables_growth_B_per_run", _get(b.get("tables_memory", {}), "growth_B_per_run"), 10.0,
        better="lower", unit="B of peak traced memory per stored run (flat: about 0)")
    row("shrink_10_faults_simulations", _get(b["shrink"], "simulations"), 150, better="lower")
    row("search_runs_to_failure_random_over_bo", _get(b["search"], "suite_ratio_random_to_bo"), 5.0,
        unit="x fewer runs than uniform (median over scenarios)")
    fault_overheads = _get(b["faults"], "overhead") or {}
    if fault_overheads:
        worst = max((v, k) for k, v in fault_overheads.items() if " " not in k)
        row("fault_overhead_worst_kind", worst[0], 0.05, better="lower", unit=f"fraction ({worst[1]})")
    row("route_cost_vs_overtake", _get(b.get("routes", {}), "route_cost_vs_overtake"), 0.10, better="lower",
        unit="fraction of the overtake run's CPU time per simulated second")
    peers = b.get("peers") or {}
    for key, value in peers.items():
        if key.startswith("ratio"):
            rows[f"peers_{key}"] = {"value": value, "target": None, "unit": "ours / peer (sim s per wall s)"}
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="bench-results.json")
    ap.add_argument("--quick", action="store_true", help="lighter settings: a smoke test of every benchmark")
    ap.add_argument("--only", nargs="*", choices=sorted(BENCHMARKS), help="run only these")
    args = ap.parse_args()
    out = Path(args.out)
    log_dir = out.with_suffix("")
    log_dir = log_dir.parent / f"{log_dir.name}-logs"
    log_dir.mkdir(parents=True, exist_ok=True)
    names = args.only or list(BENCHMARKS)
    results = {}
    started = dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds")
    for name in names:
        full, quick = BENCHMARKS[name]
        print(f"[{name}] ...", flush=True)
        results[name] = r = run_one(name, quick if args.quick else full, log_dir)
        status = "ok" if r["exit_code"] == 0 and "figures" in r else f"FAILED (exit {r['exit_code']})"
        print(f"[{name}] {status} in {r['wall_s']:.1f} s (load before {r['load_before']})", flush=True)
    doc = {
        "started": started, "commit": _git_commit(), "quick": args.quick,
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version(), "platform": platform.platform()},
        "benchmarks": results,
    }
    doc["headline"] = headline({n: results.get(n, {}) for n in BENCHMARKS})
    out.write_text(json.dumps(doc, indent=2, default=float) + "\n")
    print(f"wrote {out} (logs in {log_dir}/)")
    for key, h in doc["headline"].items():
        mark = "" if h.get("met") is None else (" met" if h["met"] else " MISSED")
        target = f" (target {h['target']:g})" if h.get("target") is not None else ""
        print(f"  {key}: {h['value']:.4g} {h['unit']}{target}{mark}")
    return 0 if all(r["exit_code"] == 0 for r in results.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
