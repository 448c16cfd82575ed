"""The docs are tested: every ```addt block in docs/language.md compiles as its comments
say, and docs/diagnostics.md lists exactly the codes in `CODES`, each with an input that
produces it."""

from __future__ import annotations

import re

import pytest
from tests.unit.compiler.conftest import REPO, describe, expectations, found

from addt_dsl.compiler import compile_source
from addt_dsl.diagnostics import CODES

DOCS = REPO / "docs"
BLOCK_RE = re.compile(r"```addt\n(.*?)```", re.S)
# Binary input, a very long line, a compiler bug, a missing torch (tests/unit/core/test_optional_deps.py).
NO_EXAMPLE = {"E0003", "E0004", "E0601", "E0900"}


def _diagnostic_sections() -> dict[str, str]:
    text = (DOCS / "diagnostics.md").read_text()
    parts = re.split(r"^### ([EW]\d{4}) .*$", text, flags=re.M)
    return dict(zip(parts[1::2], parts[2::2]))


def test_diagnostics_doc_lists_exactly_the_codes():
    sections = _diagnostic_sections()
    assert list(sections) == sorted(sections), "keep the codes in order"
    assert set(sections) == set(CODES)


@pytest.mark.parametrize("code", sorted(set(CODES) - NO_EXAMPLE))
def test_each_code_has_an_example_that_produces_it(code):
    blocks = BLOCK_RE.findall(_diagnostic_sections()[code])
    assert blocks, f"{code} has no example"
    result = compile_source(blocks[0], f"{code}.addt", base_dir=DOCS)
    assert code in {d.code for d in result.diagnostics}, describe(result)


def _language_blocks():
    text = (DOCS / "language.md").read_text()
    return [(text[: m.start()].count("\n") + 2, m.group(1)) for m in BLOCK_RE.finditer(text)]


@pytest.mark.parametrize(("line", "source"), _language_blocks(), ids=[f"line{n}" for n, _ in _language_blocks()])
def test_language_examples(line, source):
    """A block compiles cleanly, or produces exactly its `# expect:` diagnostics. A block
    with no `scenario` is a file of shared definitions: it must parse."""
    result = compile_source(source, "doc.addt", base_dir=REPO / "examples")
    if "scenario" not in source:
        assert not any(d.code in ("E0001", "E0002") for d in result.diagnostics), describe(result)
        return
    want = expectations(source)
    assert found(result) == want, describe(result)
    if not want:
        assert result.ok


def test_language_doc_covers_every_construct():
    text = (DOCS / "language.md").read_text()
    blocks = "\n".join(src for _, src in _language_blocks())
    for construct in ("scenario", "description", "duration", "step", "seed", "line", "arc", "spiral",
                      "param_poly3", "lanes", "offset", "import", "param", "dist normal", "dist choice",
                      "assume", "keep", "ego", "stack", "sensor", "goal", "agent", "pedestrian", "cyclist",
                      "ahead of", "behind", "lane of", "lane left of", "behavior", "when", "at ", "after",
                      "sequence", "parallel", "faults", "during", "from", "for", "seed", "expect",
                      "no collision", "stay in lane", "reach goal", "min ttc", "max jerk", "max latency",
                      "always", "eventually", "until", "implies", "hard", "warn", "sweep", "grid", "random",
                      "halton", "lhs", "repeat", "max_rejections", "include", "#", '"'):
        assert construct in blocks, f"no example of `{construct}` in docs/language.md"
    assert "| unit" in text.lower() or "unit |" in text.lower()


def test_language_doc_names_every_registered_element():
    from addt_dsl.registry import BEHAVIORS, FAULTS, GEOMETRIES, SENSORS, SIGNALS, STACKS

    text = (DOCS / "language.md").read_text()
    for table in (BEHAVIORS, FAULTS, GEOMETRIES, SENSORS, SIGNALS, STACKS):
        for name in table.names():
            assert f"`{name}" in text, f"docs/language.md does not mention {table.what} `{name}`"
