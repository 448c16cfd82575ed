"""Compare a run's trajectories with another player's: per entity, RMS and maximum distance [m].

The reference is a table of rows `time, entity, x, y` (esmini's `dat2csv` output, the format of
esmini's reference trajectories in `tests/data/esmini-ref/`). Both sides give the entity's
OpenSCENARIO reference point: the importer places an actor's centre there (docs/openscenario.md).
The run's samples are compared with the reference linearly interpolated at the same time, over
the span both cover; a timing tolerance of one reference step is allowed by taking, per entity,
the best of the shifts -dt, 0, +dt (esmini applies an event's action in the step its trigger
fires, one step before or after a player that evaluates triggers after moving).
"""

from __future__ import annotations

import csv
import gzip
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

TOLERANCE_M = 0.5  # the RMS a trajectory must stay within to count as the same [m]


@dataclass(frozen=True)
class Track:
    time: np.ndarray  # [s]
    x: np.ndarray  # [m]
    y: np.ndarray  # [m]


@dataclass(frozen=True)
class EntityError:
    entity: str
    rms_m: float  # [m]; NaN when the entity is missing from the run
    max_m: float  # [m]
    shift_s: float  # the timing shift that gave the figures [s]
    samples: int

    @property
    def ok(self) -> bool:
        return self.rms_m <= TOLERANCE_M


def read_reference(path: str | Path) -> dict[str, Track]:
    """Tracks by entity name from a (gzipped) esmini trajectory CSV."""
    path = Path(path)
    opener = gzip.open if path.suffix == ".gz" else open
    rows: dict[str, list[tuple[float, float, float]]] = {}
    with opener(path, "rt", newline="") as fh:
        for row in csv.DictReader(fh):
            rows.setdefault(row["entity"], []).append((float(row["time"]), float(row["x"]), float(row["y"])))
    out = {}
    for name in sorted(rows):
        a = np.array(rows[name], dtype=float)
        out[name] = Track(a[:, 0], a[:, 1], a[:, 2])
    return out


def compare(run: dict[str, Track], reference: dict[str, Track], entities: list[str] | None = None,
            step_s: float = 0.01) -> list[EntityError]:
    """One `EntityError` per reference entity (or per name in `entities`), in name order."""
    out = []
    for name in sorted(entities if entities is not None else reference):
        ref = reference[name]
        got = run.get(name)
        if got is None or len(got.time) == 0:
            out.append(EntityError(name, math.nan, math.nan, 0.0, 0))
            continue
        best = None
        for shift in (0.0, -step_s, step_s):
            t = got.time + shift
            keep = (t >= ref.time[0] - 1e-9) & (t <= ref.time[-1] + 1e-9)
            if not keep.any():
                continue
            rx = np.interp(t[keep], ref.time, ref.x)
            ry = np.interp(t[keep], ref.time, ref.y)
            d = np.hypot(got.x[keep] - rx, got.y[keep] - ry)
            cand = EntityError(name, float(np.sqrt(np.mean(d * d))), float(d.max()), shift, int(keep.sum()))
            if best is None or cand.rms_m < best.rms_m - 1e-12:
                best = cand
        out.append(best if best is not None else EntityError(name, math.nan, math.nan, 0.0, 0))
    return out


def tracks_of_trace(trace) -> dict[str, Track]:
    """The run's tracks by actor name (a runtime `Trace`)."""
    return {name: Track(np.asarray(trace.time, float), np.asarray(a.x, float), np.asarray(a.y, float))
            for name, a in trace.actors.items()}


@dataclass(frozen=True)
class ScenarioFidelity:
    scenario: str
    errors: tuple[EntityError, ...]  # one per reference entity the importer made an actor of
    imported: bool
    problem: str = ""  # why there are no figures (the import's first error)

    @property
    def ok(self) -> bool:
        return self.imported and bool(self.errors) and all(e.ok for e in self.errors)

    def ok_except(self, actor_names: set[str]) -> bool:
        rest = [e for e in self.errors if e.entity not in actor_names]
        return self.imported and bool(rest) and all(e.ok for e in rest)


def scenario_fidelity(xosc: str | Path, root: str | Path, reference: str | Path, ref_end_s: float,
                      **import_options) -> tuple[ScenarioFidelity, dict[str, str]]:
    """Import `xosc`, run its first run up to the reference's end, and compare every entity the
    reference has (and the import kept) with it. Returns the figures and the entity -> actor names."""
    from addt_dsl.interop.openscenario.importer import import_xosc
    from addt_dsl.runtime.execute import execute
    from addt_dsl.sweep import expand

    name = Path(xosc).stem
    got = import_xosc(xosc, root=root, **import_options)
    if got.plan is None:
        first = next((d.message for d in got.diagnostics if d.is_error), "not imported")
        return ScenarioFidelity(name, (), False, first), {}
    plan = got.plan.model_copy(update={"duration_s": min(got.plan.duration_s, ref_end_s + 0.05)})
    trace = execute(expand(plan).specs[0]).trace
    ref = read_reference(reference)
    tracks = tracks_of_trace(trace)
    run = {entity: tracks[actor] for entity, actor in got.entities.items() if actor in tracks}
    entities = [e for e in ref if e in got.entities]
    return ScenarioFidelity(name, tuple(compare(run, ref, entities)), True), dict(got.entities)
