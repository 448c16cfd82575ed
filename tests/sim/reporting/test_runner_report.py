"""`addtc FILE --out DIR --junit FILE`, `addtc report DIR`, and the report in a real
headless browser."""

import base64
import json
import re
import shutil
import subprocess
import tempfile
from xml.etree import ElementTree as ET

import pandas as pd
import pytest

from tests.sim.runner_simkit import addtc, limit_scenario

pytestmark = pytest.mark.slow

CHROMIUM = next((shutil.which(n) for n in ("chromium", "chromium-browser", "google-chrome") if shutil.which(n)),
                None)

# Appended to a copy of the report: after load, record which images did not decode and
# whether anything makes the page wider than the window (it must scroll inside its boxes).
IMAGE_CHECK = """<script>
window.addEventListener("load", () => {
  const bad = [...document.images].filter(i => !(i.complete && i.naturalWidth > 0)).map(i => i.alt);
  const box = document.getElementById("verdict-scroll");
  const out = document.createElement("pre");
  out.id = "image-check";
  out.textContent = JSON.stringify({images: document.images.length, broken: bad,
    signals: [...document.images].filter(i => i.alt.startsWith("signals over time") && i.naturalWidth > 0).length,
    page_width: document.documentElement.scrollWidth, window_width: window.innerWidth,
    verdict_box: box ? [box.clientWidth, box.scrollWidth] : null});
  document.body.appendChild(out);
});
</script>"""
NARROW_WINDOW = (500, 900)  # px (chromium's narrowest): narrower than the verdict table and the GIFs


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("report")
    scenario = limit_scenario(tmp, repeat=1, duration="4 s")
    out = tmp / "out"
    proc = addtc(scenario, "--jobs", "2", "--out", out, "--junit", out / "junit.xml", "--animations", "2")
    assert proc.returncode == 1, proc.stderr  # cells with limit 70 m fail
    return out


def test_run_outputs(run_dir):
    summary = json.loads((run_dir / "summary.json").read_text())
    assert (summary["runs"], summary["passed"], summary["failed"]) == (4, 2, 2)
    assert summary["failures_per_oracle"] == {"before_limit": 2}
    runs = pd.read_csv(run_dir / "runs.csv")
    assert len(runs) == 4
    assert {"run_id", "param.limit", "param.drop", "seed", "passed", "rho.before_limit", "rho.no_collision",
            "sim_time_s", "wall_time_s"} <= set(runs.columns)
    failing = runs[~runs["passed"]]
    assert (failing["param.limit"] == 70).all() and (failing["rho.before_limit"] < 0).all()
    # 50 m to go at up to 20 m/s: not before 2.5 s, and within the 4 s run.
    assert failing["first_violation_s.before_limit"].between(2.5, 4.0).all()

    suite = ET.parse(run_dir / "junit.xml").getroot().find("testsuite")
    assert (suite.get("tests"), suite.get("failures"), suite.get("errors")) == ("4", "2", "0")
    messages = [c.find("failure").get("message") for c in suite.findall("testcase") if c.find("failure") is not None]
    assert all(re.match(r"before_limit: robustness -[\d.]+ first violated at t=[23]\.\d\d s$", m) for m in messages)


def test_report_has_animations_of_the_failing_runs(run_dir):
    html = (run_dir / "report.html").read_text()
    gifs = re.findall(r'src="data:image/gif;base64,([^"]+)"', html)
    assert len(gifs) == 2
    from io import BytesIO

    from PIL import Image

    for gif in gifs:
        image = Image.open(BytesIO(base64.b64decode(gif)))
        assert image.format == "GIF" and image.n_frames > 10
    assert "not reproducible" not in html  # re-executed traces matched the stored digests
    assert len(re.findall(r"first violated at [23]\.\d\d s", html)) >= 2
    signals = re.findall(r'alt="signals over time of (c\d+-r\d+)" src="data:image/png;base64,([^"]+)"', html)
    assert len(signals) == 2  # one signal plot per animated failing run
    assert all(base64.b64decode(png)[:8] == b"\x89PNG\r\n\x1a\n" for _, png in signals)
    assert "declares no latency budget" in html  # the scenario bounds no latency


def test_report_subcommand_rebuilds_from_the_store(run_dir, tmp_path):
    target = tmp_path / "copy"
    shutil.copytree(run_dir, target)
    (target / "report.html").unlink()
    proc = addtc("report", target, "--animations", "0", "--export", target / "runs.parquet")
    assert proc.returncode == 1, proc.stderr  # the store's verdict: two runs failed
    assert (target / "report.html").exists()
    assert pd.read_parquet(target / "runs.parquet")["run_id"].tolist() == pd.read_csv(target / "runs.csv")[
        "run_id"].tolist()
    missing = addtc("report", tmp_path / "nowhere")
    assert missing.returncode == 2 and "no results store" in missing.stderr


@pytest.mark.skipif(CHROMIUM is None, reason="needs chromium (apt-get install -y chromium)")
def test_report_renders_in_headless_chromium(run_dir, tmp_path):
    page = tmp_path / "report.html"
    page.write_text((run_dir / "report.html").read_text().replace("</body>", IMAGE_CHECK + "</body>"))
    with tempfile.TemporaryDirectory() as profile:
        proc = subprocess.run(
            [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
             "--disable-background-networking", f"--user-data-dir={profile}", "--virtual-time-budget=10000",
             f"--window-size={NARROW_WINDOW[0]},{NARROW_WINDOW[1]}",
             "--dump-dom", page.as_uri()],
            capture_output=True, text=True, timeout=120)
    dom = proc.stdout
    assert proc.returncode == 0, proc.stderr[-2000:]
    table = re.search(r'<table id="verdict-table">(.*?)</table>', dom, re.S)
    assert table and table.group(1).count("<tr>") == 1 + 4
    check = json.loads(re.search(r'<pre id="image-check">(.*?)</pre>', dom, re.S).group(1))
    assert check["broken"] == []
    assert check["images"] >= 8  # success chart, 2 robustness histograms, 2 latency figures, GIFs, signal plots
    assert check["signals"] == 2
    # The body never scrolls sideways; the verdict table scrolls inside its own box.
    assert check["page_width"] <= check["window_width"], check
    assert check["verdict_box"][0] <= check["window_width"], check


def test_reach_goal_is_dated_when_it_became_certain(tmp_path):
    """`reach goal within 2 s` that fails: violated at 2.00 s (the window end), not 0.00 s,
    and the animation is not red before then."""
    from io import BytesIO

    import numpy as np
    from PIL import Image

    scenario = limit_scenario(tmp_path, repeat=1, duration="3 s", limits="200")
    text = scenario.read_text().replace("ego car on r lane -1 at 20 m speed 20 m/s {",
                                        "ego car on r lane -1 at 20 m speed 20 m/s goal 250 m {")
    scenario.write_text(text.replace("no collision", "no collision\n    reach goal within 2 s")
                        .replace("grid drop in [0, 20] %", "grid drop in [0] %"))
    out = tmp_path / "out"
    proc = addtc(scenario, "--jobs", "1", "--out", out, "--animations", "1")
    assert proc.returncode == 1, proc.stderr
    runs = pd.read_csv(out / "runs.csv")
    assert runs["first_violation_s.reach_goal"].tolist() == [2.0]
    html = (out / "report.html").read_text()
    assert "first violated at 2.00 s" in html and "first violated at 0.00 s" not in html
    gif = Image.open(BytesIO(base64.b64decode(re.search(r'src="data:image/gif;base64,([^"]+)"', html).group(1))))
    border = []
    for i in (0, gif.n_frames - 1):
        gif.seek(i)
        border.append(tuple(np.asarray(gif.convert("RGB"))[150, 2]))
    first, last = border
    assert not (first[0] > 180 and first[1] < 80), first  # no red frame at t = 0
    assert last[0] > 180 and last[1] < 80, last  # red once the violation is certain
