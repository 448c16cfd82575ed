"""`addtc map X | head` ends quietly: a reader that stops reading is not an error (it was
"error: Broken pipe", exit 3)."""

from __future__ import annotations

import os
import subprocess
import sys

from addt_dsl import cli
from tests.conftest import ROOT

ROAD = ('<road name="r{i}" length="100" id="{i}" junction="-1"><planView><geometry s="0" x="0" y="{y}" hdg="0" '
        'length="100"><line/></geometry></planView><lanes><laneSection s="0"><center><lane id="0" type="none" '
        'level="false"/></center><right><lane id="-1" type="driving" level="false"><width sOffset="0" a="3.5" '
        'b="0" c="0" d="0"/></lane></right></laneSection></lanes></road>')


def test_map_into_a_closed_pipe_ends_quietly(tmp_path):
    roads = "".join(ROAD.format(i=i, y=20 * i) for i in range(1, 1501))  # a listing of ~120 kB
    xodr = tmp_path / "big.xodr"
    xodr.write_text(f'<?xml version="1.0"?><OpenDRIVE><header revMajor="1" revMinor="6"/>{roads}</OpenDRIVE>')
    proc = subprocess.Popen([sys.executable, "-m", "addt_dsl.cli", "map", str(xodr)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, env={**os.environ, "PYTHONPATH": str(ROOT)})
    proc.stdout.close()  # the reader is gone before anything is written (as `| true`, or `| head` soon after)
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == 0, err
    assert err == ""


def test_a_broken_pipe_anywhere_in_a_command_is_exit_0(capsys):
    def command():
        raise BrokenPipeError(32, "Broken pipe")

    assert cli.guarded(command) == 0
    assert capsys.readouterr().err == ""
