"""Confinement: the one check every file the tool reads on a scenario's behalf goes through.

Includes, imported maps and the members of a suite directory name files relative to a
root directory. `confine` resolves such a name and returns the regular file it denotes,
or raises `Refused` with a stable diagnostic code and a message that shows no absolute
local path. Refused: anything that resolves outside the root (absolute paths, `..`,
symbolic links that lead out), names the OS cannot hold (too long), symbolic-link loops,
and anything that is not a regular file (directories, FIFOs, devices).
"""

from __future__ import annotations

import os
from pathlib import Path

MAX_NAME_BYTES = 255  # one path component (NAME_MAX on Linux, macOS and Windows)
MAX_PATH_BYTES = 4096  # the whole name (PATH_MAX on Linux)


class Refused(Exception):
    """A path the tool will not read: `code` is E0401 (unreadable) or E0402 (escapes the root)."""

    def __init__(self, code: str, message: str, note: str = ""):
        super().__init__(message)
        self.code = code
        self.message = message
        self.note = note


def confine(relative: str, base: Path, root: Path) -> Path:
    """The resolved regular file `relative` names, read from `base`, provided it lies under `root`."""
    if "\x00" in relative:
        raise Refused("E0401", f"'{shown(relative)}' is not a valid file name")
    too_long = next((part for part in Path(relative).parts if len(os.fsencode(part)) > MAX_NAME_BYTES), None)
    if too_long is not None or len(os.fsencode(relative)) > MAX_PATH_BYTES:
        raise Refused("E0401", f"'{shown(relative)}' is too long a file name",
                      f"limits: {MAX_NAME_BYTES} bytes per path component, {MAX_PATH_BYTES} bytes in all")
    root = root.resolve()
    try:
        candidate = (base / relative).resolve(strict=False)
    except (OSError, RuntimeError) as exc:  # RuntimeError: a symbolic-link loop (Python < 3.13)
        raise Refused("E0401", f"cannot resolve '{shown(relative)}': "
                      f"{'a symbolic-link loop' if isinstance(exc, RuntimeError) else exc.strerror or exc}") from None
    if not candidate.is_relative_to(root):
        raise Refused("E0402", f"'{shown(relative)}' is outside the scenario's directory",
                      "files may only come from the scenario's directory and below, or from under "
                      "`addtc --root DIR` (pytest: the rootdir)")
    try:
        regular = candidate.is_file()
    except OSError as exc:
        raise Refused("E0401", f"cannot read '{shown(relative)}': {exc.strerror or exc}") from None
    if not regular:
        what = "not a regular file" if candidate.exists() else "no such file"
        raise Refused("E0401", f"cannot find '{shown(relative)}'", f"looked for {candidate.relative_to(root)} in "
                      f"the scenario's directory: {what}")
    return candidate


def shown(text: str, limit: int = 80) -> str:
    """A file name as it may be printed: control characters escaped, long names shortened."""
    safe = text.encode("unicode_escape").decode("ascii") if not text.isprintable() else text
    return safe if len(safe) <= limit else safe[: limit - 3] + "..."
