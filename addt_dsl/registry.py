"""Registries: one table per extensible kind, keyed by DSL keyword.

Each behaviour, sensor, fault kind, stack, stack node and signal function is one small
class that declares its keyword and its settings (`ParamSpec`s) and registers itself
with `@REGISTRY.register`. The compiler checks names, settings and dimensions against
these tables; the runtime instantiates from the same tables. Implementation modules
must not import pybullet or torch at import time (the compiler loads them): import
those inside the methods that need them.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Generic, TypeVar

from addt_dsl.units import Dim

T = TypeVar("T")


@dataclass(frozen=True, slots=True)
class ParamSpec:
    """One setting a registered element accepts.

    `dim` is the physical dimension for numeric settings; `choices` makes it a word
    setting (`tensor weights`); `kind` is "number", "int", "word" or "name" (a
    reference to a declared road/actor) or "list".
    """

    name: str
    dim: Dim | None = None
    default: float | str | None = None
    required: bool = False
    low: float | None = None
    high: float | None = None
    choices: tuple[str, ...] | None = None
    kind: str = "number"
    doc: str = ""
    # A live setting may use signals (`speed speed(ego) + 5 km/h`): evaluated on the
    # current state at every step, so the target follows other actors.
    live: bool = False
    # Where the shrinker moves a numeric setting (None: 0 clipped into [low, high]); a count
    # whose range starts at 0 (`bitflip count 0`: no flips) keeps 1, the fault still acting.
    neutral: float | None = None


class Registry(Generic[T]):
    def __init__(self, what: str):
        self.what = what
        self._entries: dict[str, type[T]] = {}

    def register(self, cls: type[T]) -> type[T]:
        keyword = cls.keyword  # type: ignore[attr-defined]
        if keyword in self._entries and self._entries[keyword] is not cls:
            raise ValueError(f"{self.what} {keyword!r} registered twice")
        self._entries[keyword] = cls
        for alias in getattr(cls, "aliases", ()):
            self._entries[alias] = cls
        return cls

    def get(self, keyword: str) -> type[T] | None:
        _load_builtins()
        return self._entries.get(keyword)

    def __contains__(self, keyword: str) -> bool:
        return self.get(keyword) is not None

    def names(self) -> list[str]:
        _load_builtins()
        return sorted(self._entries)

    def classes(self) -> list[type[T]]:
        _load_builtins()
        return sorted(set(self._entries.values()), key=lambda c: c.keyword)  # type: ignore[attr-defined]


BEHAVIORS: Registry = Registry("behavior")
SENSORS: Registry = Registry("sensor")
FAULTS: Registry = Registry("fault")
STACKS: Registry = Registry("stack")
SIGNALS: Registry = Registry("signal")
GEOMETRIES: Registry = Registry("road geometry")
ENVIRONMENTS: Registry = Registry("environment model")

# Modules whose import registers the built-in elements. None imports pybullet or torch
# at module level (a unit test checks this).
_BUILTIN_MODULES = (
    "addt_dsl.runtime.behaviors",
    "addt_dsl.runtime.sensors",
    "addt_dsl.runtime.faults",
    "addt_dsl.runtime.signals",
    "addt_dsl.road.roadspec",
    "addt_dsl.runtime.environment",
    "addt_dsl.stack",
)
_loaded = False


def _load_builtins() -> None:
    global _loaded
    if _loaded:
        return
    _loaded = True
    for module in _BUILTIN_MODULES:
        importlib.import_module(module)
