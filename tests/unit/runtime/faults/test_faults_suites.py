"""The scenario families and the experiment suites compile and expand as documented."""

from collections import Counter

import pytest

from addt_dsl.compiler import compile_file
from addt_dsl.sweep import expand
from tests.conftest import EXAMPLES

SUITES = sorted((EXAMPLES / "suites").glob("*.addt"))
FAMILIES = ["following", "following_brake", "curve"]


@pytest.mark.parametrize("path", [EXAMPLES / f"{f}.addt" for f in FAMILIES] + SUITES, ids=lambda p: p.name)
def test_compiles_without_warnings(path):
    result = compile_file(path, root=EXAMPLES)  # the junction suites import ../maps
    assert result.ok and not result.diagnostics, [d.message for d in result.diagnostics]


def test_the_three_families_and_the_paper_s_suites_exist():
    names = {p.stem for p in SUITES}
    assert {f"table1_{f}" for f in ("following", "following_brake", "curve", "overtake")} <= names
    assert {f"bitflip_{f}_{n}" for f in ("following_brake", "curve", "overtake")
            for n in ("perception", "tracker", "planner", "control")} <= names
    assert "shift_yaw" in names


@pytest.mark.parametrize("path", [p for p in SUITES if p.stem.startswith("table1_")], ids=lambda p: p.stem)
def test_table1_suites_have_40_runs_per_drop_rate_and_stack(path):
    specs = expand(compile_file(path).plan).specs
    cells = Counter((s.params["drop_rate"], s.params["track_age"]) for s in specs)
    assert sorted({r for r, _ in cells}) == [0.01, 0.02, 0.05, 0.1]
    assert set(cells.values()) == {40}
    assert all(len(s.faults) == 1 and s.faults[0].kind == "drop" for s in specs)
    # Paired: every drop rate runs the same scenarios (seeds), each rate's 40 apart.
    seeds_by_rate = {r: sorted(s.seed for s in specs if s.params["drop_rate"] == r) for r, _ in cells}
    assert len({tuple(v) for v in seeds_by_rate.values()}) == 1
    assert len(set(seeds_by_rate[0.01])) == len(specs) // 4


@pytest.mark.parametrize("path", [p for p in SUITES if p.stem.startswith("bitflip_")], ids=lambda p: p.stem)
def test_bitflip_suites_target_a_node_with_1_to_5_flips(path):
    specs = expand(compile_file(path).plan).specs
    node = path.stem.rsplit("_", 1)[1]
    assert Counter(s.faults[0].settings["count"] for s in specs) == {n: 40 for n in (1, 2, 3, 4, 5)}
    assert {s.faults[0].target for s in specs} == {node}


def test_the_brake_family_triggers_the_emergency_brake():
    plan = compile_file(EXAMPLES / "following_brake.addt").plan
    (lead,) = plan.agents
    assert [t.clause.name for t in lead.triggers] == ["brake"]


PAPER_SUITES = [p for p in SUITES if p.stem.startswith(("paper_table1_", "bitflip_", "state_flip_", "drop_bursts_"))]


@pytest.mark.parametrize("family", ["curve", "following_brake", "overtake"])
def test_a_learned_family_differs_from_its_family_only_in_perception_and_lidar(family):
    def body(name):  # the definitions, without the leading comment block
        lines = (EXAMPLES / "suites" / "families" / f"{name}.addt").read_text().splitlines()
        return lines[next(i for i, line in enumerate(lines) if not line.startswith("#")):]

    plain, learned = body(family), body(f"{family}_learned")
    differ = [(a.strip(), b.strip()) for a, b in zip(plain, learned) if a != b]
    assert len(plain) == len(learned) and [b.split()[:4] for _, b in differ] == [
        ["stack", "bev", "perception", "learned"], ["sensor", "lidar", "rate", "10"]]
    assert differ[0][1] == differ[0][0].replace("stack bev ", "stack bev perception learned ")
    assert "channels 5 vfov 12 deg" in differ[1][1]


@pytest.mark.parametrize("path", PAPER_SUITES, ids=lambda p: p.stem)
def test_paper_suites_run_the_learned_detector_and_screen_with_ground_truth(path):
    assert compile_file(path).plan.ego.stack.settings["perception"] == "learned"
    screening = compile_file(path, stack=["perception=ground_truth"])
    assert screening.ok and not screening.diagnostics
    assert screening.plan.ego.stack.settings["perception"] == "ground_truth"


@pytest.mark.parametrize("family", ["curve", "following_brake", "overtake"])
def test_a_camera_bev_family_differs_from_its_family_only_in_perception_and_sensor(family):
    def code(name):  # the definitions without comment lines (the copies explain themselves)
        text = (EXAMPLES / "suites" / "families" / f"{name}.addt").read_text()
        return [line for line in text.splitlines() if not line.lstrip().startswith("#")]

    plain, camera = code(family), code(f"{family}_camera_bev")
    differ = [(a.strip(), b.strip()) for a, b in zip(plain, camera) if a != b]
    assert len(plain) == len(camera) and len(differ) == 2, differ
    assert differ[0][1] == differ[0][0].replace("stack bev ", "stack bev perception camera_bev ")
    assert differ[1] == ("sensor lidar rate 10 Hz rays 360 range 80 m", "sensor camera_rig rate 10 Hz")
