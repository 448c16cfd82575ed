"""The ```addt-fault examples of docs/faults.md, shared by the unit and closed-loop doc tests."""

import re
from pathlib import Path

from addt_dsl.registry import FAULTS

ROOT = Path(__file__).resolve().parent.parent
DOC = (ROOT / "docs" / "faults.md").read_text()
LINES = [line.strip() for block in re.findall(r"```addt-fault\n(.*?)```", DOC, re.S)
         for line in block.splitlines() if line.strip()]
IMAGE_KINDS = {c.keyword for c in FAULTS.classes() if c.sensor_kinds == ("camera",)}


def kind_of(line: str) -> str:
    """The fault kind of a `faults` line, after its optional timing."""
    words = line.split()
    if words[0] in ("at", "from"):
        words = words[3:]
    elif words[0] == "during":
        words = words[next(i for i, w in enumerate(words) if w.endswith("]")) + 1:]
    return words[0]


CAMERA_SCENARIO = """scenario doc {
  duration 4 s
  seed 3
  road r {
    line length 300 m
    lanes right 2 width 3.5 m
  }
  ego car on r lane -2 at 10 m speed 15 m/s {
    sensor lidar
    sensor camera width 160 height 120
  }
  expect {
    no collision
  }
  faults {
    %s
  }
}
"""


def scenario(fault_line: str) -> str:
    """A 4 s vehicle-following scenario with one fault (compile with base_dir examples/suites);
    image faults get a small scenario whose ego carries a camera."""
    if kind_of(fault_line) in IMAGE_KINDS:
        return CAMERA_SCENARIO % fault_line
    return ("scenario doc {\n  duration 4 s\n  seed 3\n"
            '  include "families/following.addt"\n'
            f"  faults {{\n    {fault_line}\n  }}\n}}\n")
