"""A write that fails for want of space names the file being written (a write or flush
raises `OSError(ENOSPC)` with no file name), for every output through the atomic writer:
`error: No space left on device: out/report.html`, not a bare `No space left on device`."""

from __future__ import annotations

import errno
import os
from pathlib import Path

import pytest

from addt_dsl import cli
from addt_dsl.errors import EXIT_INCOMPLETE
from addt_dsl.atomic import write_bytes, write_text


def _full(*args, **kwargs):
    # What a write to a full filesystem raises (as a write to /dev/full does): no file name.
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


@pytest.mark.parametrize("write", [write_text, write_bytes])
def test_a_full_disk_names_the_file_and_leaves_no_temporary(write, tmp_path, monkeypatch):
    target = tmp_path / "report.html"
    target.write_text("old")
    monkeypatch.setattr(Path, "write_text", _full)
    monkeypatch.setattr(Path, "write_bytes", _full)
    with pytest.raises(OSError) as got:
        write(target, "new" if write is write_text else b"new")
    assert got.value.errno == errno.ENOSPC and got.value.filename == str(target)
    assert target.read_text() == "old" and [p.name for p in tmp_path.iterdir()] == ["report.html"]


def test_the_cli_line_names_the_file(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(Path, "write_text", _full)
    out = tmp_path / "schema.json"
    assert cli.main(["schema", "--write", str(out)]) == EXIT_INCOMPLETE
    err = capsys.readouterr().err.strip()
    assert err == f"error: No space left on device: {out}"


def test_export_on_a_full_disk_names_the_file(tmp_path, monkeypatch, capsys):
    # `addtc export` writes through the atomic writer too: the line names the .xosc it was writing.
    from tests.conftest import EXAMPLES

    monkeypatch.setattr(Path, "write_text", _full)
    out = tmp_path / "out"
    assert cli.main(["export", str(EXAMPLES / "following.addt"), "--to", str(out)]) == EXIT_INCOMPLETE
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.startswith("error: No space left on device: ") and err.endswith(".xosc"), err
    assert str(out) in err
    assert not out.exists() or not any(p.name.endswith(".tmp") for p in out.iterdir())
