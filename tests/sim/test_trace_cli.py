"""`addtc trace`: the docs/running.md example runs as written (a passing run, re-executed
from the store), its CSV holds the signals it promises and its output is what the docs
quote. (Failing runs' plots: tests/sim/reporting/test_runner_report.py.)"""

import re
from pathlib import Path

import pandas as pd
import pytest

from addt_dsl import cli
from addt_dsl.errors import EXIT_OK, EXIT_USAGE

REPO = Path(__file__).resolve().parents[2]
DOC = REPO / "docs" / "running.md"


def _doc_commands() -> list[list[str]]:
    section = DOC.read_text().split("## Looking at one run", 1)[1]
    block = re.search(r"```bash\n(.*?)```", section, re.S).group(1)
    return [line.split()[1:] for line in block.splitlines() if line.startswith("addtc ")]


@pytest.fixture(scope="module")
def doc_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("trace")
    commands = _doc_commands()
    assert len(commands) == 2 and commands[1][0] == "trace"
    codes = []
    for argv in commands:
        argv = [str(REPO / a) if a.startswith("examples/") else str(tmp / a) if "." in a or a.endswith("/") else a
                for a in argv]
        codes.append(cli.main(argv))
    return tmp, codes


def test_doc_example_runs_as_written(doc_run, capsys):
    tmp, codes = doc_run
    assert codes == [EXIT_OK, EXIT_OK]
    signals = pd.read_csv(tmp / "c000.csv")
    assert len(signals) == 3001 and signals["time_s"].iloc[-1] == pytest.approx(30.0)
    for column in ("ego.speed", "ego.lane_offset", "lead.speed", "gap(ego,lead)", "ttc(ego,lead)", "latency.e2e",
                   "objects", "rho.no_collision", "rho.lane_keeping", "rho.reach_goal"):
        assert column in signals.columns, column
    assert (signals["rho.lane_keeping"] > 0).all()  # the run passes: every margin of an `always` stays positive
    events = pd.read_csv(tmp / "c000-events.csv")
    assert set(events["kind"]) >= {"behavior", "detections"}
    assert (tmp / "c000.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    doc = DOC.read_text()
    # The printed lines quoted in the docs are what the command prints.
    cli.main(["trace", str(tmp / "results"), "c000-r000"])
    out = capsys.readouterr().out
    for line in ("overtake c000-r000: pass", "signals (3001 samples every 0.01 s)",
                 "events: 301; 300 detections (one per sensor frame, in the CSV)"):
        assert line in out and line in doc
    for row in re.findall(r"^│ (ego\.speed|ttc\(ego,lead\)|rho\.lane_keeping) .*$", doc, re.M):
        quoted = next(line for line in doc.splitlines() if line.startswith(f"│ {row} "))
        assert quoted in out


def test_unknown_run_is_a_usage_error(doc_run, capsys):
    tmp, _ = doc_run
    assert cli.main(["trace", str(tmp / "results"), "c999-r999"]) == EXIT_USAGE
    err = capsys.readouterr().err
    assert "no run 'c999-r999'" in err and "c000-r000" in err
