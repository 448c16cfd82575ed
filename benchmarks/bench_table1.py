"""Wall time of the paper's Table 1 suite: 3 scenario families x lidar drop rates 1, 2, 5,
10 % x 240 runs = 2,880 closed-loop runs, one `addtc` command on this machine's cores.

Run: python benchmarks/bench_table1.py [--jobs 2] [--limit N] [--json out.json]

Target: under 10 minutes on a 2-core machine. `--limit N` runs only the first N runs of
each file (a smoke test; the figure is then not the target's). Also prints the success
table the suite produced (rows: families, columns: drop rates).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import _figures as figures_json

REPO = Path(__file__).resolve().parents[1]
FILES = sorted((REPO / "examples" / "suites").glob("paper_table1_*.addt"))
TARGET_S = 600.0


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--limit", type=int, default=0, help="first N runs per file only (smoke test)")
    ap.add_argument("--json", help="also write the figures here")
    args = ap.parse_args()
    load_before = figures_json.load()
    with tempfile.TemporaryDirectory(prefix="addt-table1-") as tmp:
        cmd = [sys.executable, "-m", "addt_dsl.cli", *map(str, FILES), "--by", "drop_rate",
               "--jobs", str(args.jobs), "--out", tmp, "--no-report"]
        if args.limit:
            cmd += ["--limit", str(args.limit)]
        env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
        t0 = time.perf_counter()
        proc = subprocess.run(cmd, env=env, capture_output=True, text=True, cwd=REPO)
        wall = time.perf_counter() - t0
        if proc.returncode not in (0, 1):
            print(proc.stderr[-3000:], file=sys.stderr)
            return proc.returncode
        suite = json.loads((Path(tmp) / "suite.json").read_text())
    print(proc.stdout)
    print(f"Table 1 suite: {suite['runs']} runs on {args.jobs} worker(s) in {wall:.1f} s wall "
          f"({suite['runs'] / wall * 60:.0f} runs/min); load before {load_before}, after {figures_json.load()}")
    if not args.limit:
        print(f"target: {TARGET_S:.0f} s -> ratio {wall / TARGET_S:.2f} ({'met' if wall < TARGET_S else 'MISSED'})")
    table = {f["scenario"]: {c["label"]: {"rate": c["rate"], "runs": c["runs"]} for c in f["by"]}
             for f in suite["files"]}
    figures_json.write(args.json, {
        "runs": suite["runs"], "passed": suite["passed"], "jobs": args.jobs, "wall_s": wall,
        "runs_per_min": suite["runs"] / wall * 60, "limit_per_file": args.limit or None,
        "target_s": TARGET_S, "ratio_to_target": wall / TARGET_S, "load_before": load_before,
        "success_by_drop_rate": table})
    return 0


if __name__ == "__main__":
    sys.exit(main())
