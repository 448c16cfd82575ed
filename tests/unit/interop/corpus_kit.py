"""Print the corpus tables of docs/openscenario.md: each file's import result (strict: what is
not translated refuses the file, E0803), its E0803/W0802 counts and the distinct reasons
(numbers as N, quoted names as X):
python -m tests.unit.interop.corpus_kit (esmini), ... corpus_kit carla (CARLA ScenarioRunner's
examples, with --maps tests/data/carla/maps; the W0803 notes every one of them gets, the frame
and the map found, are left out)."""

from __future__ import annotations

import re
import sys

from addt_dsl.interop.openscenario.importer import import_xosc
from tests.conftest import ROOT

ESMINI = ROOT / "tests" / "data" / "esmini"
CARLA = ROOT / "tests" / "data" / "carla"


def reason(message: str) -> str:
    text = message.split(": `")[0]  # the language form after ": `" is the same for every file
    text = re.sub(r"'[^']*'", "X", text)
    return re.sub(r"-?\d+(\.\d+)?(e-?\d+)?", "N", text)


def main(corpus: str = "esmini") -> None:
    print("| file | result | E0803 | W0802 | what is not translated or approximated |")
    print("|---|---|---|---|---|")
    folder = CARLA if corpus == "carla" else ESMINI
    for path in sorted((folder / "xosc").glob("*.xosc")):
        got = import_xosc(path, maps=[CARLA / "maps"]) if corpus == "carla" else import_xosc(path, root=ESMINI)
        errors = [d for d in got.diagnostics if d.is_error and d.code != "E0803"]
        if got.text is None and errors:
            print(f"| {path.name} | not imported: {errors[0].message} | | | |")
            continue
        counts = {code: sum(d.code == code for d in got.diagnostics) for code in ("E0803", "W0802")}
        reasons = list(dict.fromkeys(reason(d.message) for d in got.diagnostics if d.code != "W0803"))
        result = "refused (`--lenient` imports the rest)" if got.text is None else \
            "imports with diagnostics" if reasons else "imports"
        print(f"| {path.name} | {result} | {counts['E0803']} | {counts['W0802']} | {'; '.join(reasons)} |")


if __name__ == "__main__":
    main(*sys.argv[1:2])
