"""docs/paper-comparison.md: every command it gives names files that exist and compile, and
every benchmark script it names exists (the figures come from these commands)."""

import re

from tests.conftest import ROOT, assert_scenarios_compile

DOC = (ROOT / "docs" / "paper-comparison.md").read_text()


def test_scenario_files_in_commands_exist_and_compile():
    patterns = set(re.findall(r"(examples/\S+?\.addt)", DOC))
    assert len(patterns) >= 6
    assert_scenarios_compile(sorted(patterns))


def test_benchmark_scripts_named_exist():
    scripts = set(re.findall(r"benchmarks/(\w+\.py)", DOC))
    assert {"bench_stack.py", "bench_table1.py", "run_all.py"} <= scripts
    for name in scripts:
        assert (ROOT / "benchmarks" / name).exists(), name
