"""The fault registry: every kind is documented, declares its settings and targets."""

import pytest

from addt_dsl.registry import FAULTS, STACKS
from addt_dsl.runtime.faults import FaultKind

ALL = FAULTS.classes()
KEYWORDS = {c.keyword for c in ALL}


def test_the_issue_s_kinds_are_registered():
    assert {"drop", "delay", "skew", "shift", "noise", "blur", "image_noise", "occlude", "bitflip",
            "stuck", "random_value", "spike", "slow"} <= KEYWORDS


@pytest.mark.parametrize("cls", ALL, ids=lambda c: c.keyword)
def test_each_kind_is_a_small_documented_class(cls):
    impl = FAULTS.implementation(cls.keyword)
    assert issubclass(impl, cls) and issubclass(impl, FaultKind)
    assert cls.doc and cls.target_kind in ("sensor", "site", "node")
    for p in cls.params:
        assert p.doc, f"{cls.keyword}.{p.name} has no doc"
    names = [p.name for p in cls.params]
    assert len(names) == len(set(names)) and "seed" not in names  # `seed` is every fault's


def test_the_package_keeps_the_old_import_path():
    from addt_dsl.runtime.faults import FaultSchedule, flip_float64_bit  # noqa: F401
    from addt_dsl.runtime.faults import BitFlip, Drop  # noqa: F401


def test_valid_targets_follow_sensor_kind_and_stack():
    bev = STACKS.get("bev")
    sensors = {"lidar": "lidar", "gnss": "gnss", "camera": "camera"}
    assert FAULTS.get("drop").valid_targets(sensors, bev) == set(sensors)
    assert FAULTS.get("noise").valid_targets(sensors, bev) == {"lidar", "gnss"}
    for image_kind in ("blur", "image_noise", "occlude"):
        assert FAULTS.get(image_kind).valid_targets(sensors, bev) == {"camera"}
    sites = bev.fault_sites()
    assert {"perception.count", "planner.t_target", "planner.cost", "control.integral"} <= sites
    state = {"planner.state", "planner.trajectory", "tracker.tracks"}  # stored state: bit flips only
    assert FAULTS.get("bitflip").valid_targets(sensors, bev) == sites | set(bev.nodes) | state
    assert FAULTS.get("stuck").valid_targets(sensors, bev) == sites
    assert FAULTS.get("spike").valid_targets(sensors, bev) == set(bev.nodes)
    assert FAULTS.get("bitflip").valid_targets(sensors, None) == set()


def test_the_experiment_nodes_have_sites_for_the_paper_s_bitflip_study():
    nodes = STACKS.get("bev").nodes
    assert {"perception.x", "perception.y", "perception.count"} <= set(nodes["perception"])
    assert {"planner.speed", "planner.t_target", "planner.t_start", "planner.path_length"} <= set(nodes["planner"])
    assert {"control.steer", "control.accel", "control.integral"} <= set(nodes["control"])
