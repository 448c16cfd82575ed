"""Atomic file writes for every report and table: write a temporary file beside the
target, flush it to disk, then rename it over the target. A reader (or a CI job keeping
artifacts) sees the old file or the new one, never half of one; a full disk or a kill
mid-write leaves the old file and no stray temporary."""

from __future__ import annotations

import errno
import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from pathlib import Path


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A temporary path to write `path`'s new content to; renamed over `path` on success,
    removed on any error."""
    path = Path(path)
    if path.is_dir():  # refused by name: the rename would fail naming the temporary file
        raise IsADirectoryError(errno.EISDIR, os.strerror(errno.EISDIR), str(path))
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    except OSError as exc:
        raise naming(exc, path) from exc
    try:  # mkstemp makes it 0600: give it the mode a plain open() would (the user's umask) or the old file's
        os.fchmod(fd, _mode_for(path))
    except OSError:
        pass  # a filesystem without modes: whatever it gives
    finally:
        os.close(fd)
    try:
        yield Path(tmp)
        with open(tmp, "rb+") as fh:  # on disk before the rename makes it the file
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        with suppress(OSError):
            os.unlink(tmp)
        if isinstance(exc, OSError) and exc.filename in (None, tmp, Path(tmp)):  # not another file's error
            raise naming(exc, path) from exc
        raise


def naming(exc: OSError, path: str | Path) -> OSError:
    """`exc` naming the file being written: a write or flush that fails (`No space left on
    device`) names no file, and a failed temporary names one the user never asked for."""
    try:
        return type(exc)(exc.errno, exc.strerror or str(exc), str(path))
    except TypeError:  # an OSError subclass with another signature
        return OSError(exc.errno, exc.strerror or str(exc), str(path))


def _umask() -> int:
    """The process's umask, read without changing it where Linux shows it (`os.umask` can
    only be read by setting it, which would race with other threads' file creation)."""
    try:
        with open("/proc/self/status", encoding="ascii", errors="replace") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _mode_for(path: Path) -> int:
    """The mode of the file being replaced, else 0666 less the umask (as `open(path, "w")`)."""
    try:
        return path.stat().st_mode & 0o7777
    except OSError:
        return 0o666 & ~_umask()


def write_text(path: str | Path, text: str) -> Path:
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


def write_bytes(path: str | Path, data: bytes) -> Path:
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)
