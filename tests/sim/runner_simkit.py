"""Short closed-loop scenarios for the runner's sim tests (a few seconds simulated each)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]

# Lidar drops and repeats make every run's randomness matter; the station limit makes
# cell 70 m fail mid-run (first violation near 2.5 s) and cell 200 m pass.
LIMIT = """
scenario limit {
  description "ego must stay before a station limit"
  duration DURATION
  road r {
    line length 300 m
    lanes right 2 width 3.5 m
  }
  param limit = 80 m in [40 m, 200 m]
  param drop = 5 % in [0 %, 50 %]
  ego car on r lane -1 at 20 m speed 20 m/s {
    stack bev cruise_speed 20 m/s
    sensor lidar rate 10 Hz rays 180 range 60 m
  }
  agent lead car on r lane -2 at 60 m speed 15 m/s {
    behavior cruise speed 15 m/s
  }
  faults {
    drop lidar rate drop
  }
  expect {
    before_limit: always ego.s < limit
    no collision
  }
  sweep {
    grid limit in [70, 200] m
    grid drop in [0, 20] %
    repeat REPEAT
  }
}
"""


def limit_scenario(tmp_path: Path, repeat: int = 2, duration: str = "4 s", limits: str = "70, 200") -> Path:
    path = tmp_path / "limit.addt"
    text = LIMIT.replace("REPEAT", str(repeat)).replace("DURATION", duration)
    path.write_text(text.replace("grid limit in [70, 200] m", f"grid limit in [{limits}] m"))
    return path


def addtc_command(*args: str) -> list[str]:
    return [sys.executable, "-m", "addt_dsl.cli", *map(str, args)]


def addtc_env() -> dict:
    return {**os.environ, "PYTHONPATH": f"{REPO}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}


def addtc(*args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run(addtc_command(*args), env=addtc_env(), capture_output=True, text=True,
                          timeout=timeout, cwd=REPO)
