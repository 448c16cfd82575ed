"""Registries: one table per extensible kind, keyed by DSL keyword.

Each behaviour, sensor, fault kind, stack, signal function, road element and environment
model has a *spec*: a small class in a light module (`addt_dsl/specs/`, `addt_dsl/road/roadspec.py`)
that declares its keyword, its settings (`ParamSpec`s), its docs and the compile-time checks
(valid fault targets, a stack's sites), registered with `@REGISTRY.register`. The compiler,
the printer and the docs read the specs only. The *implementation* subclasses its spec and
registers with `@REGISTRY.implements`; the runtime asks for it with `implementation(keyword)`,
which imports the implementation modules the first time (so compiling a scenario never loads
the runtime or the stack). A spec module imports neither numpy-heavy code nor the runtime.
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
    """Specs by keyword (`register`, `get`, `names`, `classes`) and the implementations the
    runtime instantiates (`implements`, `implementation`).

    `specs`: the module whose import registers the specs; `implementations`: the modules whose
    import registers the implementations (loaded only by `implementation`, the runtime's call).
    A spec that is its own implementation (road elements) needs none."""

    def __init__(self, what: str, specs: str, implementations: tuple[str, ...] = ()):
        self.what = what
        self._specs_module = specs
        self._implementation_modules = implementations
        self._entries: dict[str, type[T]] = {}
        self._implementations: dict[str, type[T]] = {}
        self._specs_loaded = self._implementations_loaded = False

    def register(self, cls: type[T]) -> type[T]:
        """Register a spec under its keyword and aliases."""
        keyword = cls.keyword  # type: ignore[attr-defined]
        if keyword in self._entries and self._entries[keyword] is not cls:
            raise ValueError(f"{self.what} {keyword!r} registered twice")
        self._entries[keyword] = cls
        for alias in getattr(cls, "aliases", ()):
            self._entries[alias] = cls
        return cls

    def implements(self, cls: type[T]) -> type[T]:
        """Register the implementation of the spec it subclasses (same keyword)."""
        keyword = cls.keyword  # type: ignore[attr-defined]
        spec = self.get(keyword)
        if spec is None or not issubclass(cls, spec):
            raise ValueError(f"{self.what} {keyword!r}: {cls.__name__} implements no registered spec")
        if keyword in self._implementations and self._implementations[keyword] is not cls:
            raise ValueError(f"{self.what} {keyword!r} implemented twice")
        self._implementations[keyword] = cls
        for alias in getattr(cls, "aliases", ()):
            self._implementations[alias] = cls
        return cls

    def _load_specs(self) -> None:
        if not self._specs_loaded:
            self._specs_loaded = True
            importlib.import_module(self._specs_module)

    def get(self, keyword: str) -> type[T] | None:
        """The spec of `keyword` (or of an alias), None when there is none."""
        self._load_specs()
        return self._entries.get(keyword)

    def implementation(self, keyword: str) -> type[T]:
        """The class the runtime instantiates for `keyword`: imports the implementation
        modules on the first call. A spec without a separate implementation is its own."""
        spec = self.get(keyword)
        if spec is None:
            raise KeyError(f"no {self.what} {keyword!r}")
        if not self._implementations_loaded:
            self._implementations_loaded = True
            for module in self._implementation_modules:
                importlib.import_module(module)
        if self._implementation_modules:
            if keyword not in self._implementations:
                raise KeyError(f"{self.what} {keyword!r} has a spec but no implementation")
            return self._implementations[keyword]
        return spec

    def __contains__(self, keyword: str) -> bool:
        return self.get(keyword) is not None

    def names(self) -> list[str]:
        self._load_specs()
        return sorted(self._entries)

    def classes(self) -> list[type[T]]:
        """The specs, one per element (aliases once), by keyword."""
        self._load_specs()
        return sorted(set(self._entries.values()), key=lambda c: c.keyword)  # type: ignore[attr-defined]


BEHAVIORS: Registry = Registry("behavior", "addt_dsl.specs.behaviors", ("addt_dsl.runtime.behaviors",))
SENSORS: Registry = Registry("sensor", "addt_dsl.specs.sensors", ("addt_dsl.runtime.sensors",))
FAULTS: Registry = Registry("fault", "addt_dsl.specs.faults", ("addt_dsl.runtime.faults",))
STACKS: Registry = Registry("stack", "addt_dsl.specs.stacks", ("addt_dsl.stack",))
SIGNALS: Registry = Registry("signal", "addt_dsl.specs.signals", ("addt_dsl.runtime.signals",))
GEOMETRIES: Registry = Registry("road geometry", "addt_dsl.road.roadspec")
ENVIRONMENTS: Registry = Registry("environment model", "addt_dsl.specs.environment",
                                  ("addt_dsl.runtime.environment",))
