"""Packages outside the core install, the extra that brings each, and how to install it.

The core install (compile, run with ground-truth or camera perception, report, falsify,
shrink) needs no torch. The learned BEV detector, tensor bit flips and training need it,
and come with the `learned` extra. On Linux, PyPI's torch is the CUDA build (several GB
of nvidia-* wheels), so the CPU build is installed first from PyTorch's index; the
extra's exact pin then accepts it (`2.13.0+cpu` satisfies `==2.13.0`).

Presence is checked with `importlib.util.find_spec`: nothing here imports the package,
so the compiler can ask without loading torch.
"""

from __future__ import annotations

import importlib.util
from dataclasses import dataclass


@dataclass(frozen=True)
class Extra:
    name: str
    install: str  # shell command, run in the repository, that brings the package


EXTRAS: dict[str, Extra] = {
    "torch": Extra("learned", 'pip install torch==2.13.0 --index-url https://download.pytorch.org/whl/cpu '
                              '&& pip install -e ".[learned]"'),
    "osi3": Extra("osi", 'pip install -e ".[osi]"'),
}


def missing(module: str) -> bool:
    return importlib.util.find_spec(module) is None


def missing_message(module: str, what: str) -> str | None:
    """One line for a user whose `what` needs `module`, or None when it is installed."""
    if not missing(module):
        return None
    extra = EXTRAS[module]
    return (f"{what} needs {module}, which is not installed (the `{extra.name}` extra); "
            f"install it with: {extra.install}")
