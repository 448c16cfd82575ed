"""The same RunSpec gives the same trace on another machine: what numpy and BLAS compute
must not depend on the CPU's instruction sets. Another machine is stood in for by the same
one with numpy's SIMD dispatch cut down (`NPY_DISABLE_CPU_FEATURES`: an AVX2 machine, a
baseline x86-64 one) and OpenBLAS made to take other kernels (`OPENBLAS_CORETYPE`: one
without FMA, an AVX-512 one). Before the engine computed its transcendental functions with
the C library (`kernel.exp` ... `Libm.over`) and its small products in one order
(`kernel.matmul`), 57 of 131 example runs changed their traces under the first of these.

Runs: lidar ground truth (overtake), an OpenDRIVE map with curved lanes (ramp_merge), lidar
noise and misalignment faults (search/curve_shift), a learned detector (an NCAP AEB test).
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import HAS_TORCH

ROOT = Path(__file__).resolve().parents[3]
RUNS = [("examples/overtake.addt", 0), ("examples/ramp_merge.addt", 0),
        ("examples/search/curve_shift.addt", 0)]
if HAS_TORCH:  # (the core install has no learned detector)
    RUNS.append(("examples/suites/ncap_aeb_ccrb_learned.addt", 0))

CHILD = """
import json, sys
from addt_dsl.compiler import compile_file
from addt_dsl.runtime.execute import execute
from addt_dsl.sweep import expand
out = {}
for path, i in json.loads(sys.argv[1]):
    spec = expand(compile_file(path).plan).specs[i]
    r = execute(spec)
    out[f"{path}#{i}"] = [r.status, r.trace.digest(), r.trace.object_count.tobytes().hex()]
print(json.dumps(out))
"""

pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(platform.machine().lower() not in ("x86_64", "amd64"),
                                 reason="the stand-ins for other machines are x86-64 instruction sets")]


def digests(env: dict[str, str]) -> dict:
    done = subprocess.run([sys.executable, "-c", CHILD, json.dumps(RUNS)], cwd=ROOT, capture_output=True, text=True,
                          env={**os.environ, "PYTHONPATH": str(ROOT), **env}, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def numpy_dispatch() -> list[str]:
    """numpy's SIMD targets this machine has, lowest first."""
    from numpy._core import _multiarray_umath as m

    return [f for f in m.__cpu_dispatch__ if m.__cpu_features__.get(f)]


def test_traces_do_not_depend_on_numpys_simd_or_blass_kernels():
    here = digests({})
    assert all(status == "ok" for status, *_ in here.values()), here
    found = numpy_dispatch()
    above_avx2 = found[found.index("X86_V3") + 1:] if "X86_V3" in found else []
    others = {"OpenBLAS without FMA": {"OPENBLAS_CORETYPE": "Sandybridge"},
              "OpenBLAS's AVX-512 kernels": {"OPENBLAS_CORETYPE": "SkylakeX"}}
    if above_avx2:
        others["numpy on an AVX2 machine"] = {"NPY_DISABLE_CPU_FEATURES": " ".join(above_avx2)}
    if found:
        others["numpy without SIMD beyond its baseline"] = {"NPY_DISABLE_CPU_FEATURES": " ".join(found)}
    for label, env in others.items():
        there = digests(env)
        changed = sorted(k for k in here if here[k] != there.get(k))
        assert not changed, f"{label} ({env}): {changed}"
