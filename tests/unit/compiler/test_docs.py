"""docs/diagnostics.md lists exactly the codes in `CODES`, and docs/language.md shows every
construct and names every registered element (tests/docs_harness.py compiles and runs the
examples themselves)."""

from __future__ import annotations

import re

from addt_dsl.diagnostics import CODES
from tests.conftest import ROOT as REPO
from tests.docs_harness import blocks

DOCS = REPO / "docs"


def _diagnostic_sections() -> dict[str, str]:
    text = (DOCS / "diagnostics.md").read_text()
    parts = re.split(r"^### ([EW]\d{4}) .*$", text, flags=re.M)
    return dict(zip(parts[1::2], parts[2::2]))


def test_diagnostics_doc_lists_exactly_the_codes():
    sections = _diagnostic_sections()
    assert list(sections) == sorted(sections), "keep the codes in order"
    assert set(sections) == set(CODES)


def test_language_doc_covers_every_construct():
    text = (DOCS / "language.md").read_text()
    blocks_text = "\n".join(b.text for b in blocks("addt", doc="docs/language.md"))
    for construct in ("scenario", "description", "duration", "step", "seed", "line", "arc", "spiral",
                      "param_poly3", "lanes", "offset", "import", "param", "dist normal", "dist choice",
                      "assume", "keep", "ego", "stack", "sensor", "goal", "agent", "pedestrian", "cyclist",
                      "ahead of", "behind", "lane of", "lane left of", "behavior", "when", "at ", "after",
                      "sequence", "parallel", "faults", "during", "from", "for", "seed", "expect",
                      "no collision", "stay in lane", "reach goal", "min ttc", "max jerk", "max latency",
                      "always", "eventually", "until", "implies", "hard", "warn", "sweep", "grid", "random",
                      "halton", "lhs", "repeat", "max_rejections", "include", "#", '"'):
        assert construct in blocks_text, f"no example of `{construct}` in docs/language.md"
    assert "| unit" in text.lower() or "unit |" in text.lower()


def test_language_doc_names_every_registered_element():
    from addt_dsl.registry import BEHAVIORS, FAULTS, GEOMETRIES, SENSORS, SIGNALS, STACKS

    text = (DOCS / "language.md").read_text()
    for table in (BEHAVIORS, FAULTS, GEOMETRIES, SENSORS, SIGNALS, STACKS):
        for name in table.names():
            assert f"`{name}" in text, f"docs/language.md does not mention {table.what} `{name}`"
