"""Exit codes of every `addtc` command, and the errors that pick them.

    0  every run passed
    1  at least one run failed an oracle (the tool worked; the system under test did not)
    2  a usage or scenario error: a one-line message (or compiler diagnostics), no traceback
    3  the tool could not complete: runs crashed, timed out or ran out of memory, the
       results store is unusable, or an internal error

A CI job can tell a failed safety check (1) from a broken command line (2) and a broken
tool (3). When several apply (a suite of files), the highest code wins. This module sits
below everything that raises these errors (cli, search, runtime studies), so each can
say "usage error" without importing the command line.
"""

from __future__ import annotations

import argparse

EXIT_OK, EXIT_FAILED, EXIT_USAGE, EXIT_INCOMPLETE = 0, 1, 2, 3

# Run statuses that mean the tool, not the system under test, did not finish the run
# (`lost`: its worker was killed from outside on every attempt; such a run is never stored,
# so a resumed sweep runs it again).
INCOMPLETE_STATUSES = ("crashed", "timeout", "memory", "lost")


class UsageError(Exception):
    """A bad command line, path or option value: `error: <message>`, exit 2."""


class ToolError(Exception):
    """The tool could not complete (an unusable results store, a full disk): a one-line
    message that says what to do, exit 3, no traceback."""


def is_error_status(status: str) -> bool:
    """A run the tool did not finish (an error, not a failure: JUnit `<error>`)."""
    return status in INCOMPLETE_STATUSES


def verdict_exit_code(statuses: dict[str, int], failed: int) -> int:
    """Exit code of a set of runs from their status counts and failed-run count: 3 if any
    run did not finish (crashed, timeout, memory), else 1 if any failed, else 0."""
    if any(statuses.get(s, 0) for s in INCOMPLETE_STATUSES):
        return EXIT_INCOMPLETE
    return EXIT_FAILED if failed else EXIT_OK


def _number(kind, minimum, strict: bool, what: str):
    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
        if value != value or (value <= minimum if strict else value < minimum):  # NaN, or out of range
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}")
        return value

    parse.__name__ = what  # argparse names the type in its message
    return parse


def time_bound(text: str):
    """`--timeout`: "auto" (the bound derived from the scenario), seconds > 0, or 0 (off)."""
    if text.strip().lower() == "auto":
        return "auto"
    value = _number(float, 0.0, False, "auto, 0 (no limit) or a number of seconds > 0")(text)
    return value if value > 0 else None


time_bound.__name__ = "auto, 0 (no limit) or a number of seconds > 0"

# argparse `type=`s: a bad value is a one-line usage error (exit 2), never a traceback later.
nonneg_int = _number(int, 0, False, "an integer >= 0")
positive_int = _number(int, 0, True, "an integer > 0")
nonneg_float = _number(float, 0.0, False, "a number >= 0")
positive_float = _number(float, 0.0, True, "a number > 0")
