"""Documented limits on what one compilation reads and what one sweep may cost (docs/limits.md).

Two kinds, both in one frozen `Limits` value the compiler takes (`compile_file(path,
limits=...)`), both reported as E0701 naming the limit and how to raise it:

- **input limits** bound the compiler's own work (bytes read, roads in a map, lanes in a
  section, agents, parameters, oracles, faults). Raise one with `--max NAME=VALUE`.
- **cost thresholds** bound what a sweep will ask of the machine, from the estimate of
  `addt_dsl/cost.py` (runs, simulated seconds, agent-steps, lidar rays, memory per run).
  `--allow-large` lifts them all; `--max NAME=VALUE` raises one.

Road geometry bounds that compiler and runtime must agree on (road length, turn, lane
width...) are not here: they are constants of `addt_dsl/road/limits.py`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

GIB = 1024 ** 3
# Any number of a parameter (default, range, choices, mean, sd) or a setting, in SI units:
# finite values beyond it are refused where read (E0301). Samplers overflow on them
# (1e308 - -1e308 is inf) and no quantity of a driving scenario comes near.
MAX_ABS_NUMBER = 1.0e12


# Wall seconds `report.html` may spend animating failing runs (`--animations N` asks for
# them; each re-runs its run and draws every frame): the rest are listed, not drawn.
DEFAULT_ANIMATION_BUDGET_S = 60.0


@dataclass(frozen=True)
class Limits:
    # Input limits [count or bytes]: what one compilation may read and check.
    source_bytes: int = 1_000_000  # one .addt file (lark parses ~100-200 kB/s)
    included_bytes: int = 1_000_000  # all .addt text of one compilation, main file and includes (~8 s to parse)
    map_bytes: int = 50_000_000  # one imported .xodr file
    read_bytes: int = 200_000_000  # everything one compilation reads
    roads_per_map: int = 20_000  # <road> elements of one imported map
    lanes_per_section: int = 100  # lanes of one laneSection of an imported map
    agents: int = 1_000  # agents of one scenario (the ego not counted)
    params: int = 20_000
    oracles: int = 10_000
    faults: int = 10_000
    # Cost thresholds, from the estimate (addt_dsl/cost.py); --allow-large lifts them.
    runs: int = 1_000_000  # runs of one sweep
    sim_seconds: float = 1.0e7  # simulated seconds of one sweep (runs x duration)
    agent_steps: float = 1.0e10  # actor-steps of one sweep (runs x steps x actors)
    agent_steps_per_run: float = 5.0e7  # actor-steps of one run (steps x actors, ego included)
    lidar_rays_per_run: float = 1.0e9  # rays cast in one run (rays x channels x rate x duration)
    camera_pixels_per_run: float = 1.0e9  # pixels rendered in one run (pixels per frame x rate x duration)
    run_memory_bytes: float = 4.0 * GIB  # modelled memory of one run
    run_wall_seconds: float = 3600.0  # estimated wall time of one run on one core (cost.py's measured model)
    wall_seconds: float = 1.0e5  # estimated wall time of one sweep on one core (about 28 core-hours)
    allow_large: bool = False  # True: cost thresholds are not enforced (the estimate is still printed)
    run_cap: int = 0  # `addtc FILE --limit N` runs only the first N runs: the sweep's cost is of those (0: all)

    def raised(self, **changes) -> Limits:
        return dataclasses.replace(self, **changes)


DEFAULT = Limits()
INPUT_LIMITS = ("source_bytes", "included_bytes", "map_bytes", "read_bytes", "roads_per_map",
                "lanes_per_section", "agents", "params", "oracles", "faults")
COST_LIMITS = ("runs", "sim_seconds", "agent_steps", "agent_steps_per_run", "lidar_rays_per_run",
               "camera_pixels_per_run", "run_memory_bytes", "run_wall_seconds", "wall_seconds")


def parse_limit(text: str, limits: Limits = DEFAULT) -> Limits:
    """`NAME=VALUE` (`agents=5000`, `run_memory_bytes=16e9`) applied to `limits`; ValueError
    with the known names when it is not one."""
    name, sep, value = text.partition("=")
    name = name.strip()
    if not sep or name not in (*INPUT_LIMITS, *COST_LIMITS):
        raise ValueError(f"--max takes NAME=VALUE with NAME one of: {', '.join((*INPUT_LIMITS, *COST_LIMITS))}")
    try:
        number = float(value)
    except ValueError:
        raise ValueError(f"--max {name}: '{value}' is not a number") from None
    if not math.isfinite(number) or number < 0:
        raise ValueError(f"--max {name}: give a finite number >= 0")
    kind = type(getattr(DEFAULT, name))
    return limits.raised(**{name: kind(number)})


def how_to_raise(name: str) -> str:
    """The help line of an E0701 diagnostic."""
    if name in COST_LIMITS:
        return (f"pass `--allow-large` to run it anyway, or raise this threshold with `--max {name}=N` "
                "(docs/limits.md)")
    return f"raise it with `--max {name}=N` (docs/limits.md)"


def beyond_message(what: str, value: float, name: str, limit: float) -> str:
    return f"{what} ({_num(value)}) is beyond the limit {name} = {_num(limit)}"


def _num(value: float) -> str:
    return f"{int(value):,}" if float(value).is_integer() and abs(value) < 1e15 else f"{value:.3g}"


__all__ = ["COST_LIMITS", "DEFAULT", "DEFAULT_ANIMATION_BUDGET_S", "GIB", "INPUT_LIMITS", "MAX_ABS_NUMBER", "Limits",
           "beyond_message", "how_to_raise", "parse_limit"]
