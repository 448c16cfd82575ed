"""The calibration command runs end to end on a tiny budget and writes a model runs can load,
keeping the hand-written targets as they are."""

import json

import pytest

from addt_dsl.stack import calibrate
from addt_dsl.stack.latency import MODEL_PATH, NODES, load_models

pytestmark = [pytest.mark.torch, pytest.mark.slow]  # scans from the twin and torch: ~20 s on a loaded host


def test_calibrate_writes_a_loadable_model_and_keeps_the_targets(tmp_path, capsys):
    pytest.importorskip("torch")
    out = tmp_path / "model.json"
    assert calibrate.main(["--repeats", "3", "--scans", "2", "--write", "--out", str(out)]) == 0
    data = json.loads(out.read_text())
    shipped = json.loads(MODEL_PATH.read_text())
    assert data["targets"] == shipped["targets"]  # inputs, never rewritten by a calibration
    assert data["calibration"]["repeats"] == 3 and len(data["calibration"]["loadavg"]) == 3
    for node in NODES:
        v = data["nodes"][node]
        assert len(v["jitter_ratios"]) == len(calibrate.LEVELS)
        # A node takes time; under load a trend fitted to 2 scans may put all of it on the
        # objects (the fit clamps a negative intercept to 0).
        assert v["base_s"] >= 0 and v["per_object_s"] >= 0 and v["base_s"] + v["per_object_s"] > 0
    for target in data["targets"]:
        assert set(load_models(target, data=data)) == set(NODES)
    printed = capsys.readouterr().out
    assert "e2e first over 100 ms at" in printed and "target xavier" in printed
    # --show prints the same report from a stored file without timing anything.
    assert calibrate.main(["--show", str(out)]) == 0
    shown = capsys.readouterr().out
    assert shown and shown in printed
