"""The README's install, resolved against PyPI alone, pulls no CUDA build.

PyPI's Linux torch wheel depends on triton, cuda-toolkit and the nvidia-* libraries
(several GB); `--isolated` ignores this machine's pip configuration (which finds a local
CPU wheel), so the resolution is what a fresh machine with only PyPI would download."""

import json
import re
import shlex
import socket
import subprocess
import sys
import tomllib

import pytest

from addt_dsl import extras
from tests.conftest import ROOT

README = ROOT / "README.md"
CUDA = re.compile(r"^(nvidia-|cuda-|triton$)")


def _readme_block(heading: str) -> str:
    section = README.read_text(encoding="utf-8").split(f"## {heading}", 1)[1]
    return re.search(r"```bash\n(.*?)```", section, re.S).group(1)


def _pip_installs(block: str) -> list[list[str]]:
    commands = [c.strip() for c in block.replace("\\\n", " ").replace("\n", " && ").split("&&")]
    return [shlex.split(c)[2:] for c in commands if c.startswith("pip install")]


def _pypi_reachable() -> bool:
    try:
        socket.create_connection(("pypi.org", 443), timeout=5).close()
        return True
    except OSError:
        return False


def test_readme_install_resolves_to_no_cuda_package(tmp_path):
    [args] = _pip_installs(_readme_block("Set up and run an example"))
    assert args == ["-e", "."], "the README's install changed: keep this test running it exactly"
    if not _pypi_reachable():
        pytest.skip("PyPI is unreachable: cannot resolve the README's install (CI has PyPI and runs this)")
    report = tmp_path / "report.json"
    proc = subprocess.run([sys.executable, "-m", "pip", "install", "--isolated", "--dry-run", "--ignore-installed",
                           "--quiet", "--report", str(report), *args],
                          cwd=ROOT, capture_output=True, text=True, timeout=540)
    assert proc.returncode == 0, proc.stderr[-3000:]
    names = {item["metadata"]["name"].lower() for item in json.loads(report.read_text())["install"]}
    assert {"addt-dsl", "pybullet", "numpy"} <= names  # the report is the whole resolution
    assert "torch" not in names
    assert sorted(n for n in names if CUDA.match(n)) == []


def test_readme_gives_the_learned_extra_with_torch_cpu_build_first():
    installs = _pip_installs(_readme_block("The learned parts"))
    assert installs == _pip_installs(extras.EXTRAS["torch"].install)  # what E0601's help line says
    torch_cpu, extra = installs
    # The extra's exact pin is the CPU build's version, so installing the extra keeps that build.
    pin = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]["learned"]
    assert torch_cpu == [*pin, "--index-url", "https://download.pytorch.org/whl/cpu"] and pin[0].startswith("torch==")
    assert extra == ["-e", ".[learned]"]


def test_ci_runs_the_readme_test_commands():
    section = README.read_text(encoding="utf-8").split("## Set up and run the test suite", 1)[1].split("\n## ", 1)[0]
    commands = [c.strip() for block in re.findall(r"```bash\n(.*?)```", section, re.S)
                for c in block.replace("\\\n", " ").split("&&") if c.strip().startswith(("python -m pytest", "addtc"))]
    assert len(commands) == 3, commands
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8").splitlines()
    for command in commands:
        assert command in ci, command
