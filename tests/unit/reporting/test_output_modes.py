"""Reports and tables are written with the user's umask, as any file they create (they were
0600 whatever the umask: mkstemp's mode survived the atomic rename); a file being replaced
keeps its mode."""

from __future__ import annotations

import os
import stat

import pytest

from addt_dsl.atomic import write_bytes, write_text


@pytest.fixture
def umask():
    def set_to(mask: int) -> None:
        os.umask(mask)

    old = os.umask(0o022)
    yield set_to
    os.umask(old)


@pytest.mark.parametrize("mask, mode", [(0o022, 0o644), (0o002, 0o664), (0o077, 0o600)])
def test_new_files_follow_the_umask(tmp_path, umask, mask, mode):
    umask(mask)
    assert stat.S_IMODE(write_text(tmp_path / "summary.json", "{}\n").stat().st_mode) == mode
    assert stat.S_IMODE(write_bytes(tmp_path / "a.gif", b"GIF89a").stat().st_mode) == mode


def test_a_replaced_file_keeps_its_mode(tmp_path, umask):
    umask(0o022)
    path = write_text(tmp_path / "runs.csv", "a\n")
    path.chmod(0o640)
    write_text(path, "b\n")
    assert stat.S_IMODE(path.stat().st_mode) == 0o640 and path.read_text() == "b\n"
