"""Verdict tables and run outputs (summary.json, runs.csv)."""

from __future__ import annotations

import json
import math
from collections import Counter
from pathlib import Path

from addt_dsl.plan import ScenarioPlan


def runs_table(plan: ScenarioPlan, results):
    """One row per run: id, parameters, seed, verdict, per-oracle robustness, times."""
    import pandas as pd

    rows = []
    for r in results:
        row = {"run_id": r.run_id, "key": r.key, "seed": r.seed, "passed": r.passed, "status": r.status}
        row.update({f"param.{k}": v for k, v in sorted(r.params.items())})
        for v in r.verdicts:
            row[f"rho.{v.name}"] = v.robustness
        row["failed_oracles"] = ";".join(r.failed_oracles)
        row["sim_time_s"] = r.sim_time_s
        row["wall_time_s"] = r.wall_time_s
        row["fault_events"] = r.fault_events
        row["error"] = r.error.splitlines()[0] if r.error else ""
        rows.append(row)
    return pd.DataFrame(rows)


def summary(plan: ScenarioPlan, results, rejected: Counter | None = None) -> dict:
    failures: Counter = Counter()
    for r in results:
        for name in r.failed_oracles:
            failures[name] += 1
    return {
        "scenario": plan.name,
        "source": plan.source_file,
        "runs": len(results),
        "passed": sum(r.passed for r in results),
        "failed": sum(not r.passed for r in results),
        "failures_per_oracle": dict(sorted(failures.items())),
        "rejected_by_assumption": dict(rejected or {}),
        "sim_time_s": sum(r.sim_time_s for r in results),
        "wall_time_s": sum(r.wall_time_s for r in results),
    }


def write_outputs(out: Path, plan: ScenarioPlan, results, rejected=None) -> None:
    out.mkdir(parents=True, exist_ok=True)
    (out / "summary.json").write_text(json.dumps(summary(plan, results, rejected), indent=2) + "\n")
    runs_table(plan, results).to_csv(out / "runs.csv", index=False)


def _fmt(x: float) -> str:
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    return f"{x:.3g}"


def print_verdicts(plan: ScenarioPlan, results, fmt: str = "text") -> None:
    if fmt == "json":
        print(json.dumps(summary(plan, results), indent=2))
        return
    from rich.console import Console
    from rich.table import Table

    console = Console(highlight=False)
    names = [o.name for o in plan.oracles]
    table = Table(title=f"{plan.name}: {len(results)} run(s)")
    table.add_column("run")
    for p in sorted({k for r in results for k in r.cell} or ()):
        table.add_column(p)
    table.add_column("verdict")
    for n in names:
        table.add_column(n, justify="right")
    cell_params = sorted({k for r in results for k in r.cell})
    shown = results if len(results) <= 40 else [r for r in results if not r.passed][:40]
    for r in shown:
        by_name = {v.name: v for v in r.verdicts}
        verdict = "[green]pass[/]" if r.passed else f"[red]{'FAIL' if r.status == 'ok' else r.status.upper()}[/]"
        cells = [_fmt(r.cell[p]) for p in cell_params]
        rho = []
        for n in names:
            v = by_name.get(n)
            rho.append("-" if v is None else (f"[red]{_fmt(v.robustness)}[/]" if not v.passed else _fmt(v.robustness)))
        table.add_row(r.run_id, *cells, verdict, *rho)
    console.print(table)
    if len(results) > len(shown):
        console.print(f"(showing {len(shown)} failing runs of {len(results)})")
    s = summary(plan, results)
    console.print(f"{s['passed']} passed, {s['failed']} failed"
                  + (f"; failures per oracle: {s['failures_per_oracle']}" if s["failed"] else ""))
    for r in results:
        if r.status != "ok":
            console.print(f"[red]{r.run_id}: {r.status}: {r.error.splitlines()[0] if r.error else ''}[/]")
