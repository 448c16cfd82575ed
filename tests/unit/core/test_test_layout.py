"""The tests mirror the package: each folder under tests/unit and tests/sim is a package
folder of addt_dsl (the top-level modules' tests are in tests/unit/core and at the top of
tests/sim), and no test file name is in two folders (a failure names one file)."""

from __future__ import annotations

import os
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


def test_auto_workers_follow_the_cgroups_cpu_quota(tmp_path):
    # `-n auto` (tests/conftest.py): a container held to 1.5 cores by quota sees its host's
    # cores; the quota caps the workers (v2 `cpu.max`, v1 cfs files); no quota, the affinity.
    from tests.conftest import usable_cores

    cores = len(os.sched_getaffinity(0))
    assert usable_cores(tmp_path / "none") == cores
    (tmp_path / "v2").mkdir()
    (tmp_path / "v2" / "cpu.max").write_text("150000 100000\n")
    assert usable_cores(tmp_path / "v2") == 1
    (tmp_path / "v2" / "cpu.max").write_text("max 100000\n")
    assert usable_cores(tmp_path / "v2") == cores
    (tmp_path / "v1" / "cpu").mkdir(parents=True)
    (tmp_path / "v1" / "cpu" / "cpu.cfs_quota_us").write_text("100000\n")
    (tmp_path / "v1" / "cpu" / "cpu.cfs_period_us").write_text("100000\n")
    assert usable_cores(tmp_path / "v1") == 1
    (tmp_path / "v1" / "cpu" / "cpu.cfs_quota_us").write_text("-1\n")
    assert usable_cores(tmp_path / "v1") == cores
