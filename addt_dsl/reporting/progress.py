"""Progress of a sweep as plain lines, for logs (CI) where no progress bar can draw.

A line every `every_s` seconds of wall time or every `every_pct` % of the runs, whichever
comes first, and one at the end:

    progress: 48/160 runs (30 %), 3 failed, 2 warned, 1m12s elapsed, about 2m48s left
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable

from addt_dsl.errors import is_error_status



def _duration(seconds: float) -> str:
    seconds = int(round(seconds))
    if seconds < 60:
        return f"{seconds}s"
    minutes, seconds = divmod(seconds, 60)
    if minutes < 60:
        return f"{minutes}m{seconds:02d}s"
    hours, minutes = divmod(minutes, 60)
    return f"{hours}h{minutes:02d}m"


class ProgressLines:
    """`on_record` for `run_sweep`: counts the runs as they finish and prints a line when
    one is due. `done` runs were already in the store (a resumed sweep)."""

    def __init__(self, total: int, done: int = 0, every_s: float = 10.0, every_pct: float = 5.0,
                 write: Callable[[str], None] | None = None, clock: Callable[[], float] = time.monotonic):
        self.total, self.done, self.start_done = total, done, done
        self.every_s, self.step = every_s, max(1, int(total * every_pct / 100))
        self.failed = self.warned = self.errors = 0
        self.write = write or (lambda line: print(line, file=sys.stderr, flush=True))
        self.clock = clock
        self.started = self.last_time = clock()
        self.last_done = done

    def __call__(self, record) -> None:
        self.done += 1
        error = is_error_status(record.status)
        self.errors += error
        self.failed += not record.passed and not error
        self.warned += bool(record.warned_oracles)
        now = self.clock()
        if self.done >= self.total or now - self.last_time >= self.every_s or self.done - self.last_done >= self.step:
            self.write(self.line(now))
            self.last_time, self.last_done = now, self.done

    def line(self, now: float) -> str:
        elapsed = now - self.started
        ran = self.done - self.start_done
        pct = 100 * self.done / self.total if self.total else 100.0
        text = f"progress: {self.done}/{self.total} runs ({pct:.0f} %), {self.failed} failed"
        text += f", {self.errors} error(s)" if self.errors else ""
        text += f", {self.warned} warned" if self.warned else ""
        text += f", {_duration(elapsed)} elapsed"
        if ran and self.done < self.total:
            text += f", about {_duration(elapsed / ran * (self.total - self.done))} left"
        return text
