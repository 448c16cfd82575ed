"""Shared by the benchmark scripts: every script takes `--json PATH` and writes its figures
there as one JSON object, so `benchmarks/run_all.py` can collect them into one file."""

from __future__ import annotations

import json
import os
from pathlib import Path


def load() -> list[float]:
    """1, 5 and 15 minute load averages: the machines are shared, figures need their context."""
    return [round(x, 2) for x in os.getloadavg()]


def write(path: str | None, figures: dict) -> None:
    if path:
        Path(path).write_text(json.dumps({**figures, "load_after": load(), "cpus": os.cpu_count()},
                                         indent=2, default=float) + "\n")
