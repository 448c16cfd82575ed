"""What determines a run's result beyond its RunSpec: the code that runs it.

A RunSpec pins the scenario, parameters, seed and faults; the result also depends on the
package version, on the source that runs it (`source_files`) and on the data the stack loads
(the learned detector's weights, the latency model). `code_identity()` names them (version
and file hashes) and
`code_fingerprint()` hashes that; RunSpec keys, store plan hashes and the search's run
cache carry it, so results made by other code are never mixed with new ones.
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import json
from functools import lru_cache
from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parent
# Data files a run reads that change its result (paths inside the package).
DATA_FILES = ("stack/perception_weights.pt", "stack/latency_model.json")
# The source that runs a RunSpec: the loop, twin, faults, oracles, stack, road geometry,
# the element specs, and the plan-level modules they import. The version alone would not do:
# an editable install keeps its version across every change to the stack, and a run cache or
# store made before a change would be taken for the new code's. (The compiler, CLI and reports are left out: what the
# compiler makes is the plan, hashed on its own.)
SOURCE_DIRS = ("runtime", "stack", "road", "specs")
SOURCE_EXCLUDED = ("cli.py",)


def source_files() -> list[Path]:
    """The package's run-determining source files, in a fixed order."""
    files = [p for p in PACKAGE_DIR.glob("*.py") if p.name not in SOURCE_EXCLUDED]
    for d in SOURCE_DIRS:
        files.extend((PACKAGE_DIR / d).rglob("*.py"))
    return sorted(files, key=lambda p: p.relative_to(PACKAGE_DIR).as_posix())


@lru_cache(maxsize=1)
def _identity() -> tuple[tuple[str, str], ...]:
    try:
        version = importlib.metadata.version("addt-dsl")
    except importlib.metadata.PackageNotFoundError:
        version = "unknown"
    files = tuple((name, hashlib.sha256((PACKAGE_DIR / name).read_bytes()).hexdigest()[:16]) for name in DATA_FILES)
    source = hashlib.sha256()
    for path in source_files():
        source.update(path.relative_to(PACKAGE_DIR).as_posix().encode() + b"\0")
        source.update(path.read_bytes())
    return (("addt-dsl", version), *files, ("source", source.hexdigest()[:16]))


def code_identity() -> dict[str, str]:
    """{"addt-dsl": version, data file: sha256 prefix, "source": sha256 prefix}."""
    return dict(_identity())


def code_fingerprint() -> str:
    return hashlib.sha256(json.dumps(code_identity(), sort_keys=True).encode()).hexdigest()[:16]


def describe(identity: dict[str, str] | None) -> str:
    if not identity:
        return "code from before results were fingerprinted"
    return ", ".join(f"{k} {v}" for k, v in identity.items())
