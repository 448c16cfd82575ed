"""The example in docs/roads.md must run as written."""

import re
from pathlib import Path

DOC = Path(__file__).resolve().parents[3] / "docs" / "roads.md"


def test_roads_md_example_runs():
    blocks = re.findall(r"```python\n(.*?)```", DOC.read_text(encoding="utf-8"), flags=re.S)
    assert blocks, "docs/roads.md lost its python example"
    exec(compile(blocks[0], str(DOC), "exec"), {})
