"""The export column of the coverage table is what the exporter writes: every example and
every round-trip corpus file exported, each OpenSCENARIO action, condition and position in
the output collected by its schema path, and the set compared with `xosc_export.EXPORTED`
(both ways: nothing written undeclared, nothing declared never written)."""

from __future__ import annotations

import importlib.util
import xml.etree.ElementTree as ET

import pytest

from addt_dsl.compiler import compile_file
from addt_dsl.interop.xosc_export import EXPORTED, export_run
from addt_dsl.sweep import expand
from tests.conftest import EXAMPLES, ROOT

pytestmark = pytest.mark.skipif(importlib.util.find_spec("qc_openscenario") is None,
                                reason="the OpenSCENARIO schema comes with asam-qc-openscenarioxml")
CORPUS = sorted(EXAMPLES.glob("*.addt")) + sorted((ROOT / "tests" / "data" / "interop").glob("every_*.addt"))
# Where each category's elements stand in a file: their parents' tags.
PARENTS = {"action": ("GlobalAction", "PrivateAction", "UserDefinedAction"), "condition": ("Condition",),
           "position": ("Position",)}


def _written(root, schema: dict[str, set[str]]) -> set[str]:
    found: set[str] = set()

    def walk(el, path: tuple[str, ...], category: str) -> None:
        path = (*path, el.tag)
        if "/".join(path) in schema[category]:
            found.add("/".join(path))
        for child in el:
            walk(child, path, category)

    for category, parents in PARENTS.items():
        for tag in parents:
            for el in root.iter(tag):
                # An action's path starts at GlobalAction/PrivateAction; a condition's and a
                # position's below their element.
                for start in ([el] if category == "action" else list(el)):
                    walk(start, (), category)
    return found


def test_the_export_writes_exactly_the_declared_elements(tmp_path):
    from docs.osc_schema import table

    schema: dict[str, set[str]] = {cat: set() for cat in PARENTS}
    for e in table():
        if e.category in schema:
            schema[e.category].add(e.path)
    written: dict[str, str] = {}
    for path in CORPUS:
        result = compile_file(path)
        assert result.ok, path
        done = export_run(expand(result.plan).specs[0], tmp_path / path.stem, "x")
        for element in _written(ET.parse(done.xosc_path).getroot(), schema):
            written.setdefault(element, path.name)
    assert set(written) - set(EXPORTED) == set(), "written but not in xosc_export.EXPORTED"
    assert set(EXPORTED) - set(written) == set(), "declared in xosc_export.EXPORTED, written by no corpus file"
    assert all(p in schema["action"] | schema["condition"] | schema["position"] for p in EXPORTED)
