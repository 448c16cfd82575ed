"""`addtc trace DIR RUN_ID --osi FILE`: the run's ground truth as an OSI trace that OSI's own
reader (osi3trace.OSITrace) reads back, object poses equal to the trace's."""

import math
from pathlib import Path

import pytest

pytest.importorskip("osi3", reason="the `osi` extra (osi-python) is not installed")

from osi3trace.osi_trace import OSITrace  # noqa: E402

from addt_dsl import cli  # noqa: E402
from addt_dsl.errors import EXIT_OK, EXIT_USAGE  # noqa: E402
from addt_dsl.reporting.trace_view import rerun  # noqa: E402
from addt_dsl.stack import osi_mapping as M  # noqa: E402

pytestmark = pytest.mark.slow
REPO = Path(__file__).resolve().parents[3]


@pytest.fixture(scope="module")
def stored(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("osi")
    args = [str(REPO / "examples" / "overtake.addt"), "--limit", "1", "--out", str(tmp / "results")]
    assert cli.main(args) == EXIT_OK
    return tmp


def _trace(results: Path):
    with cli._open_store(results) as store:
        record = next(store.records("run_id = ?", ("c000-r000",), limit=1))
        return rerun(store, record)


@pytest.mark.parametrize("suffix", [".osi", ".mcap"])
def test_osi_trace_reads_back_with_the_trace_poses(stored, suffix, capsys):
    path = stored / f"c000{suffix}"
    assert cli.main(["trace", str(stored / "results"), "c000-r000", "--osi", str(path)]) == EXIT_OK
    run = _trace(stored / "results")
    trace = run.trace
    assert f"wrote {path} ({len(trace.time)} OSI SensorViews)" in capsys.readouterr().out
    reader = OSITrace(str(path), "SensorView")
    messages = list(reader)
    reader.close()
    assert len(messages) == len(trace.time)
    names = list(trace.actors)
    for k in (0, 1, len(messages) // 2, len(messages) - 1):
        sv = messages[k]
        gt = sv.global_ground_truth
        assert M.seconds(sv.timestamp) == pytest.approx(trace.time[k], abs=1e-9)
        assert gt.host_vehicle_id.value == 1 and len(gt.moving_object) == len(names)
        for name, o in zip(names, gt.moving_object):
            a = trace.actors[name]
            b = o.base
            assert (b.position.x, b.position.y, b.orientation.yaw) == (a.x[k], a.y[k], a.heading[k])
            assert (b.dimension.length, b.dimension.width) == (a.length_m, a.width_m)
            assert b.velocity.x == pytest.approx(a.speed[k] * math.cos(a.heading[k]))
    # The lanes (static) come with the first message only.
    assert len(messages[0].global_ground_truth.lane) > 0 and len(messages[1].global_ground_truth.lane) == 0


def test_osi_trace_needs_a_known_suffix(stored, capsys):
    assert cli.main(["trace", str(stored / "results"), "c000-r000", "--osi", str(stored / "x.json")]) == EXIT_USAGE
    assert "FILE.osi or FILE.mcap" in capsys.readouterr().err
