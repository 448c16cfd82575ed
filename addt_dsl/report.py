"""Compatibility shim: the reporting code lives in `addt_dsl.reporting`."""

from __future__ import annotations

import json
from pathlib import Path

from addt_dsl.reporting.tables import print_verdicts, runs_table, summary

__all__ = ["print_verdicts", "runs_table", "summary", "write_outputs"]


def write_outputs(out: Path, plan, results, rejected=None) -> None:
    """summary.json and runs.csv of in-memory results (the CLI writes them from the store)."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "summary.json").write_text(json.dumps(summary(plan, results, rejected), indent=2) + "\n")
    runs_table(plan, results).to_csv(out / "runs.csv", index=False)
