"""How far a lidar's rays meet a box standing on level ground (W0004's geometry)."""

import math

import pytest

from addt_dsl.compiler.rules.actors import lidar_reach


def test_a_level_ray_meets_only_what_is_taller_than_its_mount():
    assert lidar_reach(1.0, [0.0], 80.0, 1.0) == 0.0  # grazes the top: never inside the box
    assert lidar_reach(1.0, [0.0], 80.0, 1.4) == 80.0


def test_a_downward_ray_meets_a_low_box_until_it_reaches_the_ground():
    # The learned detector's lidar: 5 channels over 12 deg at 1 m. The -3 deg ray is below a
    # 1 m box's top from the start and meets the ground 19.08 m out; -6 deg at 9.51 m.
    elevations = [math.radians(a) for a in (-6, -3, 0, 3, 6)]
    assert lidar_reach(1.0, elevations, 80.0, 1.0) == pytest.approx(1.0 / math.tan(math.radians(3)))
    # A 0.4 m box: the -3 deg ray is under its top from 11.4 m to the ground at 19.08 m.
    assert lidar_reach(1.0, elevations, 80.0, 0.4) == pytest.approx(19.081, abs=1e-3)
    # Out of range before it comes down to the box.
    assert lidar_reach(1.0, [math.radians(-3)], 10.0, 0.4) == 0.0


def test_a_rising_ray_leaves_the_box_above_the_mount():
    assert lidar_reach(1.0, [math.radians(5)], 80.0, 0.9) == 0.0
    assert lidar_reach(1.0, [math.radians(5)], 80.0, 1.5) == pytest.approx(0.5 / math.tan(math.radians(5)))
