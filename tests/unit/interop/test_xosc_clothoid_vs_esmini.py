"""Clothoid trajectories against esmini's own path (trajectory-test.xosc's clothoid, which
esmini drives from 8.0 s to 12.0 s: curvature -0.1 1/m, curvatureDot 0.00036 1/m^2, 70 m
over 4 s)."""

from __future__ import annotations

import csv
import gzip
import math
import re
import shutil

import numpy as np

from addt_dsl.interop.openscenario.importer import import_xosc
from tests.conftest import ROOT

ESMINI = ROOT / "tests" / "data" / "esmini"
REF = ROOT / "tests" / "data" / "esmini-ref" / "traj" / "trajectory-test.csv.gz"
START = '<WorldPosition x="204.8694" y="80.5231" h="1.10011"/>'  # esmini's Target at 8.00 s
AT_ZERO = ('<ConditionGroup><Condition name="now" delay="0" conditionEdge="none"><ByValueCondition>'
           '<SimulationTimeCondition value="0" rule="greaterThan"/></ByValueCondition></Condition></ConditionGroup>')


def test_a_clothoid_from_a_world_pose_follows_esminis_path(tmp_path):
    """The clothoid starts facing the WorldPosition's h (it faced the road's heading there,
    0.019 rad off: 0.27 m RMS from esmini's path)."""
    text = (ESMINI / "xosc" / "trajectory-test.xosc").read_text()
    text = text.replace('<RelativeRoadPosition dt="0" ds="0" entityRef="Target"/>', START, 1)
    text = re.sub(r'(name="FollowTrajectoryClothoidEvent".*?<StartTrigger>).*?(</StartTrigger>)',
                  lambda m: m[1] + AT_ZERO + m[2], text, count=1, flags=re.S)
    shutil.copytree(ESMINI, tmp_path / "esmini")
    path = tmp_path / "esmini" / "xosc" / "clothoid.xosc"
    path.write_text(text)
    got = import_xosc(path, root=tmp_path / "esmini", lenient=True)
    target = next(a for a in got.plan.agents if a.name == "Target")
    clause = next(c for c in [*target.behaviors, *(t.clause for t in target.triggers)]
                  if c is not None and "x" in c.settings)
    xs, ys, ts = ([v.value for v in clause.settings[k]] for k in ("x", "y", "times"))
    assert ts[0] == 0.0 and ts[-1] == 4.0
    with gzip.open(REF, "rt") as fh:
        ref = [(float(r["time"]) - 8.0, float(r["x"]), float(r["y"])) for r in csv.DictReader(fh)
               if r["entity"] == "Target" and 8.0 - 1e-6 <= float(r["time"]) <= 12.0 + 1e-6]
    assert len(ref) == 401
    dev = [math.hypot(np.interp(t, ts, xs) - x, np.interp(t, ts, ys) - y) for t, x, y in ref]
    rms = math.sqrt(sum(d * d for d in dev) / len(dev))
    assert rms < 0.1 and max(dev) < 0.2, (rms, max(dev))
