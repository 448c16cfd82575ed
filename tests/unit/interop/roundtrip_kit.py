"""Export a run, import the export, run both and compare: verdicts and each actor's
trajectory (RMS of the position difference on the original's time grid)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from addt_dsl.compiler import compile_source
from addt_dsl.interop.xosc_export import export_run
from addt_dsl.interop.openscenario.importer import import_xosc
from addt_dsl.runtime.execute import execute
from addt_dsl.sweep import expand


@dataclass
class RoundTrip:
    verdicts_before: dict[str, bool]
    verdicts_after: dict[str, bool]
    rms_m: dict[str, float] = field(default_factory=dict)  # actor -> RMS position difference [m]
    diagnostics: list[str] = field(default_factory=list)

    @property
    def same_verdicts(self) -> bool:
        return self.verdicts_before == self.verdicts_after


def round_trip(spec, work: Path, sidecar: bool = True, original=None) -> RoundTrip:
    """`original`: the run of `spec` where the caller has it (one the session shares)."""
    done = export_run(spec, work / "xosc", "scenario")
    if not sidecar:
        done.sidecar_path.unlink()
    got = import_xosc(done.xosc_path)
    assert got.text is not None, [d.message for d in got.diagnostics]
    back = work / "addt"
    back.mkdir(parents=True, exist_ok=True)
    for name, body in got.side_files.items():
        (back / name).write_text(body)
    result = compile_source(got.text, "scenario.addt", base_dir=back)
    assert result.ok, [d.message for d in result.diagnostics]
    (again,) = expand(result.plan).specs
    a, b = original or execute(spec), execute(again)
    out = RoundTrip({v.name: v.passed for v in a.verdicts}, {v.name: v.passed for v in b.verdicts},
                    diagnostics=[f"{d.code} {d.message}" for d in got.diagnostics])
    ta, tb = a.trace, b.trace
    for name, track in ta.actors.items():
        other = tb.actors[name]
        n = min(len(ta.time), len(tb.time))
        t = ta.time[:n]
        x = np.interp(t, tb.time, other.x)
        y = np.interp(t, tb.time, other.y)
        out.rms_m[name] = float(np.sqrt(np.mean((track.x[:n] - x) ** 2 + (track.y[:n] - y) ** 2)))
    return out


def main() -> None:
    """Print the round-trip figures of every example, with and without the side file
    (docs/openscenario.md): python -m tests.unit.interop.roundtrip_kit"""
    import tempfile

    from tests.conftest import EXAMPLES, ROOT, needs_torch
    from addt_dsl.compiler import compile_file

    paths = sorted(EXAMPLES.glob("*.addt")) + [ROOT / "tests" / "data" / "interop" / f"{n}.addt"
                                            for n in ("every_behavior", "every_action", "every_light")]
    print("| example | side file | same verdicts | RMS per actor [m] |")
    print("|---|---|---|---|")
    for path in paths:
        if needs_torch(path):
            continue
        spec = expand(compile_file(path).plan).specs[0]
        for sidecar in (True, False):
            with tempfile.TemporaryDirectory() as tmp:
                got = round_trip(spec, Path(tmp), sidecar=sidecar)
            rms = ", ".join(f"{k} {v:.3g}" for k, v in got.rms_m.items())
            if sidecar:
                same = "yes" if got.same_verdicts else "no"
            else:  # the import's default oracle is `no collision`: compare that one
                key = "no_collision"
                same = "yes" if got.verdicts_before.get(key) == got.verdicts_after.get(key) else "no"
            print(f"| {path.stem} | {'with' if sidecar else 'without'} | {same} | {rms} |")


if __name__ == "__main__":
    main()
