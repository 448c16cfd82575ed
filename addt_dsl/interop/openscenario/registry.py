"""Element registries: each OpenSCENARIO element the importer knows is one entry, with its status
and what differs or why it is refused. The translator dispatches through them (an action, a
condition, a position type: its registered function); an element in no registry is refused
like one registered as refused (E0803, or W0801 with `--lenient`).

Statuses: `exact` (translated as OpenSCENARIO 1.3 defines it and esmini executes it),
`approx` (translated with a W0802 diagnostic saying what differs; the note says when),
`refused` (not translated; the note names what the language or the twin lacks).
`openscenario.coverage.coverage()` lists every registry as data (for docs/regen.py)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

STATUSES = ("exact", "approx", "refused")


@dataclass(frozen=True)
class ElementEntry:
    family: str  # "action", "condition", "position", "storyboard"
    name: str  # the OpenSCENARIO element's name
    status: str  # one of STATUSES
    note: str  # what differs (approx), why it is refused (refused), or where it applies
    translate: Callable | None  # the translation (an unbound method of the importer); None: none here


class ElementRegistry:
    def __init__(self, family: str):
        self.family = family
        self._entries: dict[str, ElementEntry] = {}

    def _add(self, name: str, status: str, note: str, translate) -> None:
        if status not in STATUSES:
            raise ValueError(f"{name}: status {status!r} is not one of {STATUSES}")
        if name in self._entries:
            raise ValueError(f"{self.family} {name} is registered twice")
        self._entries[name] = ElementEntry(self.family, name, status, note, translate)

    def register(self, name: str, status: str, note: str = ""):
        """A decorator: `fn` translates element `name` (several names may share one function)."""
        def add(fn):
            self._add(name, status, note, fn)
            return fn
        return add

    def declare(self, name: str, status: str, note: str) -> None:
        """An element handled without a function of its own (by the walk of the document) or
        refused: documented here, so that the coverage table lists it."""
        self._add(name, status, note, None)

    def translator(self, name: str):
        """The function that translates element `name`; None: refused (or unknown)."""
        entry = self._entries.get(name)
        return entry.translate if entry is not None else None

    def entries(self) -> list[ElementEntry]:
        return [self._entries[n] for n in sorted(self._entries)]


ACTIONS = ElementRegistry("action")  # in an event
INIT_ACTIONS = ElementRegistry("action in Init")  # private actions in the storyboard's Init
GLOBAL_ACTIONS = ElementRegistry("global action")  # in an event
INIT_GLOBAL_ACTIONS = ElementRegistry("global action in Init")
VALUE_CONDITIONS = ElementRegistry("condition")  # in a ByValueCondition
ENTITY_CONDITIONS = ElementRegistry("condition")  # in a ByEntityCondition
POSITIONS = ElementRegistry("position")
STORYBOARD = ElementRegistry("storyboard")
DISTRIBUTIONS = ElementRegistry("distribution")  # a ParameterValueDistribution's (distribution.py)
REGISTRIES = (ACTIONS, INIT_ACTIONS, GLOBAL_ACTIONS, INIT_GLOBAL_ACTIONS, VALUE_CONDITIONS, ENTITY_CONDITIONS,
              POSITIONS, STORYBOARD, DISTRIBUTIONS)
