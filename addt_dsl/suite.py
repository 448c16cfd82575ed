"""Suites: several `.addt` files run by one `addtc` command, with one combined table.

    addtc run examples/suites/table1/ --by drop_rate --out OUT

A directory stands for the `.addt` files directly in it (sorted; files it `include`s
from elsewhere are not run on their own). Each file is an ordinary run with its own
results directory `OUT/<file stem>/`; the suite adds `OUT/suite.json` and prints one
row per file: runs, passes and, with `--by PARAM`, the success rate for each value of
that parameter — the layout of the paper's Table 1 (rows: scenario families, columns:
frame-drop rates).
"""

from __future__ import annotations

import json
import math
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from addt_dsl.confine import Refused, confine
from addt_dsl.atomic import write_text
from addt_dsl.reporting.tables import fmt_param, terminal
from addt_dsl.stats import wilson_interval
from addt_dsl.reporting.summary import store_summary


class SuiteError(ValueError):
    """A path that names no scenario file."""


def expand_paths(paths: Sequence[str]) -> list[Path]:
    """Files as given, directories as their `.addt` files (sorted, not recursive). A
    directory's members go through the same confinement as includes: one that is a
    symbolic link leading out of the directory (or a FIFO, a loop, ...) is refused."""
    files: list[Path] = []
    for raw in paths:
        p = Path(raw)
        if p.is_dir():
            found = []
            for q in sorted(p.glob("*.addt")):
                if q.is_dir() and not q.is_symlink():
                    continue  # a directory named like a scenario is not one
                try:
                    confine(q.name, p, p)
                except Refused as refused:
                    raise SuiteError(f"{q}: {refused.message}" + (f" ({refused.note})" if refused.note else "")) \
                        from None
                found.append(q)
            if not found:
                raise SuiteError(f"{raw}: no .addt files in this directory")
            files += found
        elif p.is_file():
            files.append(p)
        else:
            raise SuiteError(f"{raw}: no such file or directory")
    seen: set[Path] = set()
    unique = []
    for f in files:  # a file named twice runs once
        if f.resolve() not in seen:
            seen.add(f.resolve())
            unique.append(f)
    return unique


# Outcome classes a fault can cause (addt_dsl.runtime.outcome.FAULT_OUTCOMES): a classified
# run in another class (`twin_failed`, `error`) says nothing about the fault.
FAULT_OUTCOMES = ("masked", "silent", "detected", "hazard")


@dataclass
class Tally:
    runs: int = 0
    passed: int = 0
    outcomes: Counter = field(default_factory=Counter)  # with --classify: runs per outcome class
    samples: int = 0  # with --classify: runs whose fault-free twin passed
    samples_passed: int = 0

    @property
    def rated(self) -> tuple[int, int]:
        """(passed, runs) the success rate is over: with --classify only the runs whose
        fault-free twin passed, else every run."""
        return (self.samples_passed, self.samples) if self.outcomes else (self.passed, self.runs)

    @property
    def rate(self) -> float:
        k, n = self.rated
        return k / n if n else math.nan

    def as_dict(self) -> dict:
        lo, hi = wilson_interval(*self.rated)
        out = {"runs": self.runs, "passed": self.passed, "rate": self.rate, "interval95": [lo, hi]}
        if self.outcomes:
            out["outcomes"] = dict(self.outcomes)
            out["fault_samples"], out["fault_samples_passed"] = self.samples, self.samples_passed
        return out


@dataclass
class SuiteRow:
    """One file of a suite after its run."""

    path: Path
    name: str = ""
    exit_code: int = 0
    totals: dict = field(default_factory=dict)
    by: dict[float, Tally] = field(default_factory=dict)  # value of the `--by` parameter → tally
    labels: dict[float, str] = field(default_factory=dict)  # value → label with its unit
    wall_s: float = 0.0


def tally_by(records: Iterable, param: str) -> dict[float, Tally]:
    """Runs and passes per value of `param` (a sweep axis or any run parameter)."""
    out: dict[float, Tally] = {}
    for r in records:
        value = r.cell.get(param, r.params.get(param))
        if value is None:
            continue
        t = out.setdefault(float(value), Tally())
        t.runs += 1
        t.passed += r.passed
        if getattr(r, "outcome", ""):
            t.outcomes[r.outcome] += 1
            if r.outcome in FAULT_OUTCOMES:
                t.samples += 1
                t.samples_passed += r.passed
    return dict(sorted(out.items()))


def collect_row(row: SuiteRow, plan, store, by: str | None) -> None:
    """Fill `row` from a finished run's plan and store (called before the store closes)."""
    row.name = plan.name
    row.totals = store_summary(store)
    if by:
        row.by = tally_by(store.records(), by)
        row.labels = {v: fmt_param(plan, by, v) for v in row.by}


def suite_summary(rows: Sequence[SuiteRow], by: str | None) -> dict:
    return {
        "by": by,
        "files": [{
            "path": str(r.path), "scenario": r.name, "exit_code": r.exit_code, "wall_s": r.wall_s,
            "runs": r.totals.get("runs", 0), "passed": r.totals.get("passed", 0),
            "failed": r.totals.get("failed", 0), "errors": r.totals.get("errors", 0),
            "warned": r.totals.get("warned", 0),
            **({"outcomes": r.totals["outcomes"]} if "outcomes" in r.totals else {}),
            "by": [{"value": v, "label": r.labels.get(v, f"{v:g}"), **t.as_dict()} for v, t in r.by.items()],
        } for r in rows],
        "runs": sum(r.totals.get("runs", 0) for r in rows),
        "passed": sum(r.totals.get("passed", 0) for r in rows),
        "failed": sum(r.totals.get("failed", 0) for r in rows),
        "errors": sum(r.totals.get("errors", 0) for r in rows),
        "warned": sum(r.totals.get("warned", 0) for r in rows),
        "wall_s": sum(r.wall_s for r in rows),
    }


def write_summary(out: Path, rows: Sequence[SuiteRow], by: str | None) -> Path:
    out.mkdir(parents=True, exist_ok=True)
    path = out / "suite.json"
    write_text(path, json.dumps(suite_summary(rows, by), indent=2) + "\n")
    return path


def print_suite(rows: Sequence[SuiteRow], by: str | None) -> None:
    """One row per file; with `by`, success rates per value (runs per cell in brackets).
    Classified (`--classify`): the rate is over the runs whose fault-free twin passed, in
    brackets their number, the runs left out (`+N twin failed`, runner errors included) and
    the 95 % Wilson interval."""
    from rich.table import Table

    values = sorted({v for r in rows for v in r.by})
    labels = {}
    for r in rows:
        labels.update(r.labels)
    title = f"suite: {len(rows)} file(s)" + (f", success rate by {by}" if by else "")
    table = Table(title=title)
    for col in ("scenario", "runs", "passed", "wall [s]"):
        table.add_column(col, justify="left" if col == "scenario" else "right")
    classified = any("outcomes" in r.totals for r in rows)
    if classified:
        table.add_column("masked/silent/detected/hazard/twin_failed", justify="right")
    for v in values:
        table.add_column(labels.get(v, f"{v:g}"), justify="right")
    for r in rows:
        cells = []
        for v in values:
            t = r.by.get(v)
            if t is None:
                cells.append("-")
                continue
            # Classified: the rate and n are over runs whose twin passed; the others are counted apart.
            apart = t.runs - t.rated[1]
            lo, hi = wilson_interval(*t.rated)
            cells.append(f"{100 * t.rate:.2f}% ({t.rated[1]}" + (f", +{apart} twin failed" if apart else "")
                         + (f"; {100 * lo:.1f}-{100 * hi:.1f}" if t.outcomes else "") + ")")
        colour = "green" if r.exit_code == 0 else ("red" if r.exit_code == 1 else "yellow")
        outcomes = r.totals.get("outcomes", {})
        kinds = ("masked", "silent", "detected", "hazard", "twin_failed")
        counts = ["/".join(str(outcomes.get(k, 0)) for k in kinds)] if classified else []
        table.add_row(f"[{colour}]{r.name or r.path.stem}[/]", str(r.totals.get("runs", 0)),
                      str(r.totals.get("passed", 0)), f"{r.wall_s:.1f}", *counts, *cells)
    console = terminal()  # off a terminal (CI logs): full width, no column cut
    console.print(table)
    total = sum(r.totals.get("runs", 0) for r in rows)
    passed = sum(r.totals.get("passed", 0) for r in rows)
    warned = sum(r.totals.get("warned", 0) for r in rows)
    console.print(f"{passed} of {total} runs passed in {sum(r.wall_s for r in rows):.1f} s"
                  + (f"; {warned} run(s) with warnings" if warned else ""))
