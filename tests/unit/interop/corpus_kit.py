"""Print the esmini corpus table of docs/openscenario.md: each file's import result, its
W0801/W0802 counts and the distinct reasons (numbers as N, quoted names as X):
python -m tests.unit.interop.corpus_kit"""

from __future__ import annotations

import re

from addt_dsl.interop.xosc_import import import_xosc
from tests.conftest import ROOT

ESMINI = ROOT / "tests" / "data" / "esmini"


def reason(message: str) -> str:
    text = message.split(": `")[0]  # the language form after ": `" is the same for every file
    text = re.sub(r"'[^']*'", "X", text)
    return re.sub(r"-?\d+(\.\d+)?(e-?\d+)?", "N", text)


def main() -> None:
    print("| file | result | W0801 | W0802 | what is not translated or approximated |")
    print("|---|---|---|---|---|")
    for path in sorted((ESMINI / "xosc").glob("*.xosc")):
        got = import_xosc(path, root=ESMINI)
        errors = [d for d in got.diagnostics if d.is_error]
        if got.text is None:
            print(f"| {path.name} | not imported: {errors[0].message if errors else '?'} | | | |")
            continue
        counts = {code: sum(d.code == code for d in got.diagnostics) for code in ("W0801", "W0802")}
        reasons = list(dict.fromkeys(reason(d.message) for d in got.diagnostics))
        result = "imports with diagnostics" if reasons else "imports"
        print(f"| {path.name} | {result} | {counts['W0801']} | {counts['W0802']} | {'; '.join(reasons)} |")


if __name__ == "__main__":
    main()
