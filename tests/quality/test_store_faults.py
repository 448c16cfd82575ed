"""A damaged, foreign, read-only, locked or full results store: refused in one
line that names the file, what is wrong and what to do, exit 3, never a traceback and never
overwritten; what was committed is kept and a resume ends with the results of an
uninterrupted run (0 lost, 0 duplicated, identical verdicts and digests)."""

from __future__ import annotations

import contextlib
import os
import shutil
import sqlite3
import subprocess

import pytest

from tests.quality.crashkit import assert_same_results, reference, rows, sweep_file
from tests.sim.runner_simkit import addtc

from addt_dsl.errors import EXIT_FAILED, EXIT_INCOMPLETE, EXIT_OK
from addt_dsl.runtime.store import ResultStore

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def sweep(tmp_path_factory):
    """(scenario, the uninterrupted run's rows, a finished store to break copies of)."""
    tmp = tmp_path_factory.mktemp("store-faults")
    scenario = sweep_file(tmp, repeat=5, duration="3 s")  # 20 runs, cell limit=70 m fails
    expected = reference(scenario, tmp)
    return scenario, expected, tmp / "reference.sqlite"


def _one_line_error(result, *fragments) -> str:
    err = result.stderr.strip().splitlines()
    assert result.returncode == EXIT_INCOMPLETE, result.stderr
    assert "Traceback" not in result.stderr
    line = err[-1]
    assert line.startswith("error: ")
    for f in fragments:
        assert f in line, line
    return line


def _copy(src, dst):
    shutil.copyfile(src, dst)
    return dst


def _page_of(path, needle: bytes) -> int:
    data = path.read_bytes()
    page_size = int.from_bytes(data[16:18], "big")
    return data.index(needle) // page_size, page_size


def test_truncated_store(sweep, tmp_path):
    scenario, expected, good = sweep
    store = _copy(good, tmp_path / "results.sqlite")
    with open(store, "r+b") as fh:
        fh.truncate(store.stat().st_size * 6 // 10)
    damaged = store.read_bytes()
    line = _one_line_error(addtc("report", store), str(store), "damaged", "--salvage")
    assert addtc(scenario, "--store", store, "--no-report").returncode == EXIT_INCOMPLETE
    assert store.read_bytes() == damaged, "a damaged store is never written"
    assert line.count("\n") == 0


def test_garbage_header_and_foreign_files_are_refused_not_overwritten(sweep, tmp_path):
    scenario, _, good = sweep
    garbage = _copy(good, tmp_path / "garbage.sqlite")
    with open(garbage, "r+b") as fh:
        fh.write(os.urandom(100))
    empty = tmp_path / "empty.sqlite"
    empty.write_bytes(b"")
    text = tmp_path / "notes.sqlite"
    text.write_text("my notes, not a store\n")
    other_db = tmp_path / "other.sqlite"
    with contextlib.closing(sqlite3.connect(other_db)) as db:
        db.execute("CREATE TABLE customers (name TEXT)")
        db.commit()
    for path, what in ((garbage, "not an SQLite file"), (empty, "is empty (0 bytes)"), (text, "not an SQLite file"),
                       (other_db, "not a results store (tables: customers)")):
        before = path.read_bytes()
        _one_line_error(addtc(scenario, "--store", path, "--no-report"), str(path), what)
        _one_line_error(addtc("report", path), str(path), what)
        assert path.read_bytes() == before, f"{path.name} was changed"


def test_a_malformed_page_is_refused_then_salvaged_and_resumed(sweep, tmp_path):
    scenario, expected, good = sweep
    store = _copy(good, tmp_path / "results.sqlite")
    page, size = _page_of(store, b'"run_id":"c001-r002"')  # a leaf page of the runs table
    with open(store, "r+b") as fh:
        fh.seek(page * size)
        fh.write(b"\xff" * size)
    _one_line_error(addtc("report", store), str(store), "is damaged", "--salvage NEW.sqlite")
    salvaged = tmp_path / "salvaged.sqlite"
    result = addtc("report", store, "--salvage", salvaged)
    assert result.returncode == EXIT_OK, result.stderr
    kept = rows(salvaged)
    assert 0 < len(kept) < len(expected) and set(kept) <= set(expected)
    assert f"salvaged {len(kept)} run(s) into {salvaged}" in result.stdout
    resumed = addtc(scenario, "--store", salvaged, "--no-report")
    assert resumed.returncode == EXIT_FAILED, resumed.stderr
    assert f"({len(kept)} run(s) taken from the store, {len(expected) - len(kept)} executed now)" in resumed.stderr
    assert_same_results(rows(salvaged), expected)


@contextlib.contextmanager
def _mounted_tmpfs(path, size: str):
    """A small tmpfs at `path` (root only); skips the test with the reason where it cannot."""
    if os.geteuid() != 0:
        pytest.skip("needs root to mount a small tmpfs (a full or read-only filesystem)")
    path.mkdir()
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path)],
                             capture_output=True, text=True)
    if mounted.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here ({mounted.stderr.strip() or mounted.returncode})")
    try:
        yield path
    finally:
        subprocess.run(["umount", "-l", str(path)], check=False)


@contextlib.contextmanager
def _read_only_dir(tmp_path, store):
    """`store` copied into a read-only directory: a read-only mount as root (permissions do
    not stop root), else a directory and file without write permission."""
    if os.geteuid() != 0:
        ro = tmp_path / "ro"
        ro.mkdir()
        copy = _copy(store, ro / "results.sqlite")
        copy.chmod(0o444)
        ro.chmod(0o555)
        try:
            yield copy
        finally:
            ro.chmod(0o755)
        return
    with _mounted_tmpfs(tmp_path / "ro", "4M") as ro:
        copy = _copy(store, ro / "results.sqlite")
        subprocess.run(["mount", "-o", "remount,ro", str(ro)], check=True)
        yield copy


def test_read_only_store_reports_and_refuses_a_sweep(sweep, tmp_path):
    scenario, expected, good = sweep
    with _read_only_dir(tmp_path, good) as store:
        out = tmp_path / "report"
        result = addtc("report", store, "--out", out, "--animations", "0", "--export", tmp_path / "runs.parquet")
        assert result.returncode == EXIT_FAILED, result.stderr  # the store's verdicts, read without writing
        assert (out / "report.html").exists() and (tmp_path / "runs.parquet").exists()
        _one_line_error(addtc(scenario, "--store", store, "--no-report"), str(store), "--store")
        assert rows(store) == expected


def test_a_locked_store_is_refused_naming_the_holder_and_still_readable(sweep, tmp_path):
    scenario, expected, good = sweep
    store = _copy(good, tmp_path / "results.sqlite")
    with ResultStore(store):  # this process is the writer
        line = _one_line_error(addtc(scenario, "--store", store, "--no-report", "--fresh"), str(store))
        assert f"in use by another sweep (pid {os.getpid()}:" in line
        report = addtc("report", store, "--out", tmp_path / "r", "--animations", "0")
        assert report.returncode == EXIT_FAILED, report.stderr  # readers take no lock
    assert_same_results(rows(store), expected)  # --fresh discarded nothing


def test_a_full_disk_stops_the_sweep_cleanly_and_resume_completes(sweep, tmp_path):
    scenario, expected, _ = sweep
    with _mounted_tmpfs(tmp_path / "small", "1M") as fs:
        out = fs / "out"
        filler = fs / "filler"
        free = os.statvfs(fs).f_bavail * os.statvfs(fs).f_frsize
        filler.write_bytes(b"\0" * (free - 192 * 1024))  # room for a few commits, not for 20 runs
        full = addtc(scenario, "--jobs", "2", "--out", out, "--animations", "0")
        _one_line_error(full, "the disk is full", "every run committed so far is kept", "run the same command again")
        kept = rows(out / "results.sqlite")
        assert 0 < len(kept) < len(expected) and set(kept) <= set(expected)
        assert not (out / "report.html").exists()
        filler.unlink()
        resumed = addtc(scenario, "--jobs", "2", "--out", out, "--animations", "0")
        assert resumed.returncode == EXIT_FAILED, resumed.stderr
        assert_same_results(rows(out / "results.sqlite"), expected)
        report = (out / "report.html").read_bytes()
        # The report cannot be rewritten on a full disk: the old one stays whole, no temporary stays.
        free = os.statvfs(fs).f_bavail * os.statvfs(fs).f_frsize
        filler.write_bytes(b"\0" * max(0, free - 8 * 1024))
        again = addtc("report", out, "--animations", "0")
        _one_line_error(again, "No space left on device", str(out))  # names the file it was writing
        assert (out / "report.html").read_bytes() == report
        assert not [p for p in out.iterdir() if p.name.endswith(".tmp")]
