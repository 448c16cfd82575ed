"""The import coverage table of docs/openscenario.md: every action, condition, position type,
storyboard element and parameter distribution of the OpenSCENARIO 1.3 schema (docs/osc_schema.py),
each with the status the
importer's own registries give it (addt_dsl/interop/openscenario/registry.py): `exact`, `approx`
(translated with a W0802 diagnostic; the note says what differs) or `refused` (E0803 unless
`--lenient`; the note says what the twin or the language lacks). An element in no registry is
refused. Distributions are the logical-scenario importer's (openscenario/distribution.py). The
export column is `xosc_export.EXPORTED`: the elements an export writes, and the constructs that
write them (tests/unit/interop/test_export_coverage.py checks it against real exports).

    python -m docs.osc_coverage [--xsd-dir DIR]
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from pathlib import Path

from addt_dsl.interop.openscenario.coverage import status_of
from addt_dsl.interop.xosc_export import EXPORTED
from docs.osc_schema import table

CATEGORIES = ("action", "condition", "position", "storyboard", "distribution")
UNKNOWN = "not in the importer's registries"
IN_INIT = "in Init, positions, speeds, routes, trajectories, controllers, the environment and lights are"


def rows(directory: Path | None = None) -> list[tuple[str, str, bool, dict]]:
    """(category, schema path, in 1.2, {context: entry or None}) of each schema element."""
    return [(e.category, e.path, e.in_1_2, status_of(e.category, e.path))
            for e in table(directory) if e.category in CATEGORIES]


def _cell(entry) -> str:
    return entry.status if entry is not None else "refused"


def _note(entry, unknown: str = UNKNOWN) -> str:
    return (entry.note if entry is not None else unknown).replace("|", "\\|")


def markdown(directory: Path | None = None) -> str:
    found = rows(directory)
    counts = Counter(_cell(entry) for _, _, _, by in found for entry in by.values())
    lines = [f"{len(found)} elements of OpenSCENARIO 1.3; statuses (an action counted in an event and in Init): "
             + ", ".join(f"{counts[s]} {s}" for s in ("exact", "approx", "refused")) + ".", "",
             f"An export writes {len(EXPORTED)} of them (the `export` column: what writes each).", "",
             "| category | element | in 1.2 | import | note | export |", "|---|---|---|---|---|---|"]
    for category, path, in_1_2, by in found:
        if category == "action":
            event, init = by["event"], by["Init"]
            status = f"event: {_cell(event)}; Init: {_cell(init)}" if _cell(event) != _cell(init) or \
                (event is not init and _note(event) != _note(init)) else _cell(event)
            note = _note(event) if _note(event) == _note(init) else \
                f"event: {_note(event)}; Init: {_note(init, IN_INIT)}"
        else:
            entry = by[""]
            status, note = _cell(entry), _note(entry)
        written = EXPORTED.get(path, "-").replace("|", "\\|")
        lines.append(f"| {category} | `{path}` | {'yes' if in_1_2 else 'no'} | {status} | {note} | {written} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--xsd-dir", type=Path, help="a folder with 1.2.0/OpenSCENARIO.xsd and 1.3.0/OpenSCENARIO.xsd")
    args = parser.parse_args(argv)
    sys.stdout.write(markdown(args.xsd_dir))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
