"""The tests mirror the package: each folder under tests/unit and tests/sim is a package
folder of addt_dsl (the top-level modules' tests are in tests/unit/core and at the top of
tests/sim), and no test file name is in two folders (a failure names one file)."""

from __future__ import annotations

from collections import Counter

from tests.conftest import ROOT

PACKAGE = ROOT / "addt_dsl"
TESTS = ROOT / "tests"
DATA_FOLDERS = {"cases", "hostile", "__pycache__"}  # compiler test data, not tests


def _test_folders(base):
    for path in sorted(base.rglob("*")):
        if path.is_dir() and not DATA_FOLDERS & set(path.relative_to(base).parts):
            yield path.relative_to(base)


def test_every_unit_and_sim_test_folder_is_a_package_folder():
    stray = [f"unit/{rel}" for rel in _test_folders(TESTS / "unit")
             if rel.parts[0] != "core" and not (PACKAGE / rel / "__init__.py").exists()]
    stray += [f"sim/{rel}" for rel in _test_folders(TESTS / "sim") if not (PACKAGE / rel / "__init__.py").exists()]
    assert not stray, f"test folders that are no addt_dsl package: {stray}"


def test_no_test_file_name_in_two_folders():
    names = Counter(p.name for p in TESTS.rglob("*.py")
                    if p.name != "__init__.py" and p.name != "conftest.py"
                    and not DATA_FOLDERS & set(p.relative_to(TESTS).parts))
    assert not [n for n, k in names.items() if k > 1]
