"""The importer's registries as data: each OpenSCENARIO element it knows, with its status and
note (registry.py). `coverage()` is what a coverage table is built from (docs/osc_coverage.py
joins it with the OpenSCENARIO 1.3 schema); `status_of(category, path)` answers for one schema
element path, e.g. ("action", "PrivateAction/LongitudinalAction/SpeedAction")."""

from __future__ import annotations

from addt_dsl.interop.openscenario import distribution, importer  # noqa: F401 - they register their elements
from addt_dsl.interop.openscenario.registry import (ACTIONS, DISTRIBUTIONS, ENTITY_CONDITIONS, GLOBAL_ACTIONS,
                                                    INIT_ACTIONS, INIT_GLOBAL_ACTIONS, POSITIONS, REGISTRIES,
                                                    STORYBOARD, VALUE_CONDITIONS, ElementEntry, ElementRegistry)


def coverage() -> list[ElementEntry]:
    """Every registered element of every registry (family, name, status, note), sorted."""
    return [entry for registry in REGISTRIES for entry in registry.entries()]


def _lookup(registry: ElementRegistry, path: str) -> ElementEntry | None:
    """The entry of a schema path: the whole path, else its last segment that has an entry
    (a wrapper's entry, e.g. AppearanceAction, stands for the elements under it)."""
    entries = {e.name: e for e in registry.entries()}
    if path in entries:
        return entries[path]
    return next((entries[seg] for seg in reversed(path.split("/")) if seg in entries), None)


def status_of(category: str, path: str) -> dict[str, ElementEntry | None]:
    """The entries that answer for a schema element: by context (an action: in an event and in
    Init). None where no registry has it (the import refuses it)."""
    if category == "action" and path.split("/")[0] in ("GlobalAction", "UserDefinedAction"):
        return {"event": _lookup(GLOBAL_ACTIONS, path), "Init": _lookup(INIT_GLOBAL_ACTIONS, path)}
    if category == "action":
        return {"event": _lookup(ACTIONS, path), "Init": _lookup(INIT_ACTIONS, path)}
    if category == "condition":
        registry = VALUE_CONDITIONS if path.startswith("ByValueCondition") else ENTITY_CONDITIONS
        return {"": _lookup(registry, path)}
    if category == "position":
        return {"": _lookup(POSITIONS, path)}
    if category == "storyboard":
        return {"": _lookup(STORYBOARD, path)}
    if category == "distribution":
        return {"": _lookup(DISTRIBUTIONS, path)}
    return {}
