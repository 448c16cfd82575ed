"""Shared by the benchmark scripts: the paper's scenario families (examples/suites/families)
as single RunSpecs, with ground-truth or learned perception and optional fault lines."""

from __future__ import annotations

import tempfile
from pathlib import Path

SUITES = Path(__file__).resolve().parents[1] / "examples" / "suites"
# The paper families: overtaking, large-curvature turning, following with braking, plain following.
PAPER_FAMILIES = ("overtake", "curve", "following_brake", "following")
FAMILY_LIDAR = "sensor lidar rate 10 Hz rays 360 range 80 m"


def family_spec(family: str, perception: str = "ground_truth", duration_s: float = 30.0, faults: str = "",
                seed: int = 2024):
    """The family's default parameters, `step 10 ms`, fault-free unless `faults` (DSL lines).

    With `perception learned`, the ego carries the lidar the detector is trained for
    (`bev_grid.DETECTOR_LIDAR`), as in bench_stack.py.
    """
    from addt_dsl.compiler import compile_source
    from addt_dsl.sweep import expand

    text = (SUITES / "families" / f"{family}.addt").read_text()
    if perception != "ground_truth":
        assert "stack bev " in text and FAMILY_LIDAR in text, family
        text = text.replace("stack bev ", f"stack bev perception {perception} ")
        if perception == "learned":
            from addt_dsl.stack.bev_grid import DETECTOR_LIDAR

            text = text.replace(FAMILY_LIDAR, DETECTOR_LIDAR.clause())
    src = (f"scenario bench_{family} {{\n  duration {duration_s:g} s\n  step 10 ms\n  seed {seed}\n"
           f'  include "families/{family}.addt"\n'
           + (f"  faults {{\n    {faults}\n  }}\n" if faults else "") + "}\n")
    with tempfile.TemporaryDirectory() as tmp:
        (Path(tmp) / "families").mkdir()
        (Path(tmp) / "families" / f"{family}.addt").write_text(text)
        result = compile_source(src, f"bench_{family}.addt", base_dir=Path(tmp))
    assert result.ok, result.diagnostics
    return expand(result.plan).specs[0]
