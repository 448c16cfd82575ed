"""Writing a shrunk failure: the pinned `.addt` file, its trace, a report, an animation.

The `.addt` file is replayed right after it is written (compiled from disk and run):
its run must fail the same way and give the trace digest the shrinker saw, bit for bit,
or writing fails. Outputs, for a stem `S`:

    S.addt          the minimal counterexample; `addtc S.addt` replays it (exit 1)
    S.trace.npz     every signal of the replay (`time`, `<actor>.<field>`, `latency.<node>`, ...)
    S.events.json   the replay's events (fault injections with their values, collisions)
    S.report.json   target failure, per-pass statistics, what did not matter
    S.gif           top-down animation, when the reporting package provides one
    S.xosc          the same run as OpenSCENARIO XML, with its road (S.xodr or the imported
                    map) and S.addt.json (what OpenSCENARIO cannot hold), addt_dsl/interop
    S.osi           the replay's ground truth as an ASAM OSI trace (the `osi` extra; without
                    it, `Artifacts.osi_note` says so)
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from addt_dsl.interop.xodr_export import ExportError
from addt_dsl.interop.xosc_export import export_run
from addt_dsl.plan import RunSpec
from addt_dsl.printer import compile_pinned, print_spec, semantic_key, side_files
from addt_dsl.atomic import write_text
from addt_dsl.search.outcome import evaluate


class ReplayMismatch(RuntimeError):
    """The written file does not replay the shrunk run."""


class NotCompilable(ReplayMismatch):
    """The shrunk run printed as `.addt` does not compile (nothing of it is written)."""


@dataclass
class Artifacts:
    addt: Path
    trace: Path
    events: Path
    report: Path
    animation: Path | None = None
    files: list[Path] = field(default_factory=list)
    xosc: Path | None = None  # the OpenSCENARIO replay file (None: the run has no OpenSCENARIO form)
    xosc_note: str = ""  # why not
    osi: Path | None = None  # the replay's ground truth as an ASAM OSI trace (None: see osi_note)
    osi_note: str = ""  # why not (the `osi` extra is not installed)


# The header line that ties a counterexample to the content of the scenario it was shrunk
# from (`printer.semantic_key` of its plan): an edited scenario does not replay it.
SCENARIO_KEY_LABEL = "scenario key:"


def counterexample_stem(source_file: str, spec: RunSpec) -> str:
    stem = Path(source_file).stem if source_file else spec.plan.name
    return f"{stem}-{semantic_key(spec)[:8]}"


def header_comment(result, source_file: str) -> str:
    f = result.target
    lines = [f"Minimal counterexample, written by addtc shrink from {source_file or '<spec>'}"
             + (f" ({result.original.run_id})" if result.original.run_id else ""),
             f"source: {source_file}" if source_file else "source: -",
             *([f"{SCENARIO_KEY_LABEL} {result.scenario_key}"] if getattr(result, "scenario_key", "") else []),
             f"fails: {f.describe()}",
             f"shrunk in {result.simulations} simulations ({result.cache_hits} cache hits, {result.rounds} rounds)",
             "replay: addtc THIS_FILE  (exit 1)"]
    lines += result.changes
    return "\n".join(lines)


def shared_map_name(road) -> str:
    """`town-3fa2c1d9e0b4.xodr`: an imported map by its name and the hash of its content."""
    digest = hashlib.sha256((road.xodr_text or "").encode()).hexdigest()[:12]
    stem = Path(road.xodr_file or road.name).stem
    return f"{stem.removesuffix('-' + digest)}-{digest}.xodr"


def shared_maps(spec: RunSpec) -> RunSpec:
    """The run with each imported map named by its content: counterexamples written to one
    directory share one file per map (a 1 MB map is not copied per entry), and a map edited
    since never overwrites the one an older entry replays (the name changes with the content)."""
    roads = [r.model_copy(update={"xodr_file": shared_map_name(r)}) if r.source == "xodr" else r
             for r in spec.plan.roads]
    return spec.model_copy(update={"plan": spec.plan.model_copy(update={"roads": roads})})


def _holds(path: Path, text: str) -> bool:
    try:
        return path.is_file() and path.read_text() == text
    except (OSError, UnicodeDecodeError):
        return False


def write_counterexample(result, out_dir: str | Path, source_file: str = "", stem: str | None = None,
                         animate: bool = True) -> Artifacts:
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    stem = stem or counterexample_stem(source_file, result.best)
    best = shared_maps(result.best)
    text = print_spec(best, comment=header_comment(result, source_file))
    path = out / f"{stem}.addt"
    written = []
    for name, body in side_files(best.plan).items():
        if not _holds(out / name, body):  # named by content: one copy however many entries import it
            write_text(out / name, body)
        written.append(out / name)
    try:  # compiled before it is written: a counterexample that does not compile is never left behind
        replay = compile_pinned(text, path=str(path), base_dir=out)
    except ValueError as exc:
        raise NotCompilable(f"the shrunk run cannot be written as a scenario that compiles: {exc}") from None
    write_text(path, text)
    written.insert(0, path)
    outcome = evaluate(replay, keep_trace=True)
    trace = outcome.trace
    if outcome.failure(result.target.id) is None or outcome.digest != result.outcome.digest:
        raise ReplayMismatch(f"{path} does not replay the shrunk run "
                             f"(digest {outcome.digest[:12]} vs {result.outcome.digest[:12]})")
    arts = Artifacts(path, out / f"{stem}.trace.npz", out / f"{stem}.events.json", out / f"{stem}.report.json")
    if trace is not None:
        np.savez_compressed(arts.trace, **trace_arrays(trace))
        write_text(arts.events, json.dumps([{"time_s": e.time_s, "kind": e.kind, "detail": _jsonable(e.detail)}
                                           for e in trace.events], indent=1) + "\n")
        written += [arts.trace, arts.events]
        arts.osi, arts.osi_note = _osi_trace(replay, trace, out / f"{stem}.osi")
        if arts.osi is not None:
            written.append(arts.osi)
        if animate:
            arts.animation = _animation(replay, trace, outcome, out / f"{stem}.gif")
            if arts.animation:
                written.append(arts.animation)
    try:  # the same run for esmini or CARLA (docs/openscenario.md)
        exported = export_run(replay, out, stem)
        arts.xosc = exported.xosc_path
        written += [p for p in (exported.xosc_path, exported.xodr_path, exported.sidecar_path) if p not in written]
    except ExportError as exc:
        arts.xosc_note = str(exc)
    write_text(arts.report, json.dumps(report(result, source_file, path), indent=2) + "\n")
    written.append(arts.report)
    arts.files = written
    return arts


def _osi_trace(spec: RunSpec, trace, path: Path) -> tuple[Path | None, str]:
    """The replay as an OSI trace (`.osi`: what OSI tools replay, docs/bridge.md), or why not."""
    from addt_dsl import extras

    missing = extras.missing_message("osi3", f"an OSI trace ({path.name})")
    if missing:
        return None, missing
    from addt_dsl.stack import osi_trace

    osi_trace.write(spec, trace, path)
    return path, ""


def trace_arrays(trace) -> dict[str, np.ndarray]:
    from addt_dsl.runtime.trace import ACTOR_FIELDS

    arrays = {"time": trace.time}
    for name, track in trace.actors.items():
        for f in ACTOR_FIELDS:
            arrays[f"{name}.{f}"] = getattr(track, f)
    for name, values in trace.latency.items():
        arrays[f"latency.{name}"] = values
    for name, values in trace.outputs.items():
        arrays[f"output.{name}"] = values
    if trace.object_count is not None:
        arrays["objects"] = trace.object_count
    for name, state in trace.steps.items():  # named steps: 0 waiting, 1 started, 2 ended
        arrays[f"step.{name}"] = state
    return arrays


def _animation(spec: RunSpec, trace, outcome, path: Path) -> Path:
    from addt_dsl.reporting.animation import render_gif  # matplotlib: only when drawing

    path.write_bytes(render_gif(spec.plan, trace, outcome.verdicts, label=spec.plan.name))
    return path


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.floating, float)):
        return float(x) if math.isfinite(x) else repr(float(x))
    if isinstance(x, np.integer):
        return int(x)
    return x


def report(result, source_file: str, path: Path) -> dict:
    return {
        "source": source_file,
        "counterexample": str(path),
        "target": {"oracle": result.target.oracle, "mode": result.target.mode, "time_s": result.target.time_s,
                   "robustness": _jsonable(result.target.robustness)},
        "original_key": result.original.key(),
        "shrunk_key": result.best.key(),
        "faults": {"before": len(result.original.faults), "after": len(result.best.faults)},
        "agents": {"before": len(result.original.plan.agents), "after": len(result.best.plan.agents)},
        "simulations": result.simulations,
        "batch": result.batch,  # candidates run together (`--batch`)
        "ran_ahead": result.ran_ahead,  # runs a batch ran ahead that the shrink never judged
        "cache_hits": result.cache_hits,
        "rounds": result.rounds,
        "budget_exhausted": result.budget_exhausted,
        "seconds": round(result.seconds, 3),
        "passes": [asdict(s) for s in result.stats],
        "changes": result.changes,
    }
