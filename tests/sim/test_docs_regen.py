"""The command outputs printed in the docs are what the commands print now (docs/regen.py),
up to wall times and tool versions."""

import pytest

from docs.regen import DOC_FILES, ROOT, doc_blocks, mask, regenerate

pytestmark = pytest.mark.slow
DOCS = [p for p in DOC_FILES if any("regen" in b.attrs for b in doc_blocks(p)) or "<!-- regen=" in p.read_text()]


def test_the_docs_show_regenerated_outputs():
    names = {p.name for p in DOCS}
    assert {"falsify-and-shrink.md", "ci.md", "diagnostics.md", "running.md"} <= names, names


@pytest.mark.parametrize("path", DOCS, ids=[p.name for p in DOCS])
def test_doc_outputs_are_up_to_date(path):
    assert mask(regenerate(path)) == mask(path.read_text(encoding="utf-8")), \
        f"{path.relative_to(ROOT)} is out of date: run `python docs/regen.py {path.relative_to(ROOT)}`"
