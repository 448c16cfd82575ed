"""Shared fixtures: paths and compiled examples; `--no-skips` for CI."""

from __future__ import annotations

import importlib.util
import os
import re
from pathlib import Path

import pytest

# The report tables take their width from COLUMNS where it is set (else a wide one off a
# terminal); pytest-xdist's workers set COLUMNS=80, cutting the columns tests read. A test
# of the width sets COLUMNS itself.
os.environ.pop("COLUMNS", None)

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "examples"

HAS_TORCH = importlib.util.find_spec("torch") is not None
# Test inputs (scenario sources, files, doc code blocks) that need the `learned` extra.
# A suite that includes a learned family (`families/*_learned.addt`) needs it too.
_TORCH_INPUT = re.compile(r"perception\s+(learned|camera_bev)\b|perception=(learned|camera_bev)\b"
                          r"|_(learned|camera_bev)\.addt\b|^\s*import torch\b"
                          r"|addt_dsl\.stack\.(learned|tensorfaults|train|camera_bev|camera_train)\b", re.M)


def needs_torch(value) -> bool:
    """Whether a test input (source text, an .addt path, or a docs code block) needs torch."""
    if isinstance(value, Path) and value.suffix == ".addt" and value.is_file():
        value = value.read_text(encoding="utf-8")
    value = getattr(value, "text", value)  # a docs code block (tests/docs_harness.Block)
    return isinstance(value, str) and _TORCH_INPUT.search(value) is not None


@pytest.hookimpl(tryfirst=True)  # before `-m` deselects by marker
def pytest_collection_modifyitems(items):
    """A test case whose parameter needs torch (a learned scenario, a doc block importing
    torch) gets the `torch` marker, and is skipped, with its reason, where torch is missing.
    Whole modules that need torch mark themselves (`pytestmark`, `importorskip`)."""
    for item in items:
        callspec = getattr(item, "callspec", None)
        if callspec is not None and any(needs_torch(v) for v in callspec.params.values()):
            item.add_marker(pytest.mark.torch)
            if not HAS_TORCH:
                item.add_marker(pytest.mark.skip(reason="needs torch (the `learned` extra, see README)"))


@pytest.fixture(scope="session")
def ten_faults_shrunk(tmp_path_factory):
    """`addtc shrink examples/ten_faults.addt --no-animation --format json --batch N --out DIR`,
    run once per session for each N: N -> (DIR, the finished process). The same command is
    the reference of the shrink batch test, of the killed and resumed shrink, and the source
    of the replayable .xosc; each took its own shrink before. Tests only read DIR."""
    from tests.sim.runner_simkit import addtc

    done = {}

    def shrink(batch: int):
        if batch not in done:
            out = tmp_path_factory.mktemp(f"ten_faults_batch{batch}") / "out"
            done[batch] = out, addtc("shrink", EXAMPLES / "ten_faults.addt", "--no-animation", "--format", "json",
                                     "--batch", str(batch), "--out", out)
        return done[batch]
    return shrink


def compiled_as_installed(result) -> bool:
    """A scenario compiles, or (core install) its only errors are E0601: it needs torch."""
    errors = {d.code for d in result.diagnostics if d.is_error}
    return result.ok or (not HAS_TORCH and errors == {"E0601"})


@pytest.fixture(scope="session")
def overtake_plan():
    from addt_dsl.compiler import compile_file

    result = compile_file(EXAMPLES / "overtake.addt")
    assert result.ok, result.diagnostics
    return result.plan


def assert_scenarios_compile(patterns) -> None:
    """Every glob pattern (relative to the repository) names files, and each compiles:
    docs that give commands over examples must not point at missing or broken files."""
    from addt_dsl.compiler import compile_file

    for pattern in patterns:
        paths = sorted(ROOT.glob(pattern))
        assert paths, pattern
        for path in paths:
            result = compile_file(path)
            assert compiled_as_installed(result), (path, [str(d) for d in result.diagnostics])


def usable_cores(cgroup: Path = Path("/sys/fs/cgroup")) -> int:
    """The cores this process may use: its CPU affinity, capped by its cgroup's CPU quota
    (v2 `cpu.max`, v1 `cpu.cfs_quota_us` / `cpu.cfs_period_us`) where one is set: a
    container limited by quota still sees every core of its host."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    quota = None
    try:
        text = (cgroup / "cpu.max").read_text().split()
        if text and text[0] != "max":
            quota = int(text[0]) / int(text[1])
    except (OSError, ValueError, IndexError):
        try:
            q = int((cgroup / "cpu" / "cpu.cfs_quota_us").read_text())
            if q > 0:
                quota = q / int((cgroup / "cpu" / "cpu.cfs_period_us").read_text())
        except (OSError, ValueError, ZeroDivisionError):
            pass
    if quota is not None:
        cores = min(cores, max(1, int(quota)))
    return max(1, cores)


WORKER_MEMORY_BYTES = 3 * 2**30  # a worker that ran the learned and Ray tests peaks near 2 GB


def pytest_xdist_auto_num_workers(config):
    """`-n auto`: one worker per usable core, at most one per `WORKER_MEMORY_BYTES` of memory."""
    try:
        memory = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        memory = None
    workers = usable_cores()
    if memory:
        workers = min(workers, max(1, memory // WORKER_MEMORY_BYTES))
    return workers


def pytest_addoption(parser):
    parser.addoption("--no-skips", action="store_true",
                     help="fail the run if any test is skipped (CI installs every optional tool: chromium, "
                          "the ASAM OpenDRIVE checker, torch, so a skip there means a test silently did not run)")


def pytest_sessionfinish(session):
    if not session.config.getoption("no_skips"):
        return
    reporter = session.config.pluginmanager.get_plugin("terminalreporter")
    skipped = reporter.stats.get("skipped", []) if reporter is not None else []
    if skipped and session.exitstatus == pytest.ExitCode.OK:
        reporter.write("\n")  # after the progress dots, which end without a newline
        reporter.write_sep("=", f"--no-skips: {len(skipped)} test(s) skipped (reasons in the short test summary)",
                           red=True)
        session.exitstatus = pytest.ExitCode.TESTS_FAILED
