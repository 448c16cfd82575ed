"""Specs apart from implementations (addt_dsl/registry.py, addt_dsl/specs/).

The compiler reads specs only: compiling every example and suite in a fresh interpreter
loads no runtime or stack module (nor pybullet, torch, scipy). Every spec has one
implementation that subclasses it, and the runtime gets it from the registry.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import pytest

from addt_dsl import registry
from tests.conftest import EXAMPLES, HAS_TORCH

TABLES = (registry.BEHAVIORS, registry.SENSORS, registry.FAULTS, registry.STACKS, registry.SIGNALS,
          registry.ENVIRONMENTS)
FORBIDDEN = ("addt_dsl.runtime", "addt_dsl.stack", "pybullet", "torch", "scipy")


def test_compiling_every_example_loads_no_runtime_stack_or_heavy_module():
    # Included fragments (`shared/`, `suites/families/`) are compiled through the files that
    # include them; `--root examples` lets the suites reach `examples/maps/`.
    files = sorted(str(p) for p in EXAMPLES.rglob("*.addt") if p.parent.name not in ("shared", "families"))
    assert len(files) > 30 and any("/suites/" in f for f in files)
    code = textwrap.dedent(f"""
        import json
        import sys
        from addt_dsl.compiler import compile_file
        from addt_dsl import registry
        errors = {{}}
        for f in {files!r}:
            codes = sorted({{d.code for d in compile_file(f, root={str(EXAMPLES)!r}).diagnostics if d.is_error}})
            if codes:
                errors[f] = codes
        for table in (registry.BEHAVIORS, registry.SENSORS, registry.FAULTS, registry.STACKS,
                      registry.SIGNALS, registry.ENVIRONMENTS, registry.GEOMETRIES):
            table.classes()
        print(json.dumps(errors))
        print(sorted(m for m in sys.modules if m.split(".")[0] in ("pybullet", "torch", "scipy")
                     or m.startswith(("addt_dsl.runtime", "addt_dsl.stack"))))
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    errors, loaded = out.strip().splitlines()
    # A core install (no torch) refuses the learned-perception scenarios with E0601 only.
    assert all(not HAS_TORCH and codes == ["E0601"] for codes in json.loads(errors).values()), errors
    assert loaded == "[]", f"compiling loaded {loaded}"


def test_the_check_sees_a_runtime_load():
    # The subprocess check above can fail: asking for an implementation loads the runtime.
    code = ("import sys\nfrom addt_dsl.registry import FAULTS\nFAULTS.implementation('drop')\n"
            "print('addt_dsl.runtime.faults' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "True"


@pytest.mark.parametrize("table", TABLES, ids=lambda t: t.what)
def test_every_spec_has_one_implementation_that_subclasses_it(table):
    for spec in table.classes():
        impl = table.implementation(spec.keyword)
        assert impl is not spec and issubclass(impl, spec), spec.keyword
        assert impl.__module__.startswith(("addt_dsl.runtime", "addt_dsl.stack")), impl
        assert spec.__module__.startswith("addt_dsl.specs"), spec
        for alias in getattr(spec, "aliases", ()):
            assert table.implementation(alias) is impl


def test_road_elements_are_their_own_implementation():
    for spec in registry.GEOMETRIES.classes():
        assert registry.GEOMETRIES.implementation(spec.keyword) is spec


def test_an_implementation_needs_a_registered_spec():
    class Nowhere:
        keyword = "no_such_behaviour"

    with pytest.raises(ValueError, match="implements no registered spec"):
        registry.BEHAVIORS.implements(Nowhere)
    with pytest.raises(KeyError):
        registry.BEHAVIORS.implementation("no_such_behaviour")
