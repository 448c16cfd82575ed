"""`bev.lidar_sight`: how far a lidar is sure to return `min_hits` rays from a car head-on
(the pass rule's sight distance), against a hand calculation."""

import math

import pytest

from addt_dsl.runtime.sensors import Extrinsics
from addt_dsl.stack.bev import SIGHT_TARGET_WIDTH_M, lidar_sight


def _lidar(rays=360, channels=1, vfov_deg=10.0, range_m=80.0):
    return dict(rays=rays, channels=channels, fov=2 * math.pi, vfov=math.radians(vfov_deg), range=range_m)


def test_one_level_channel():
    # floor(w / (d * 1 deg)) >= 2  <=>  d <= w / (2 * pi / 180): 54.4 m for the 1.9 m car,
    # on the 0.5 m grid 54.0 m.
    expected = SIGHT_TARGET_WIDTH_M / (2.0 * math.radians(1.0))
    got = lidar_sight(_lidar(), Extrinsics(), 2)
    assert expected - 0.5 < got <= expected


def test_the_default_five_channels_add_the_one_degree_down_beam():
    # Beams at 0, -1, ... -4 deg from 1 m: the -1 deg beam meets the car's box (above the
    # road) to 57.3 m, one ray each on two beams to there (w / (d * 1 deg) >= 1).
    got = lidar_sight(_lidar(channels=5, vfov_deg=4.0), Extrinsics(pitch=math.radians(2.0)), 2)
    assert got == pytest.approx(57.0)


def test_fine_rays_reach_the_range():
    assert lidar_sight(_lidar(rays=1440, range_m=200.0), Extrinsics(), 2) == 200.0
    assert lidar_sight(_lidar(), Extrinsics(), 1) == 80.0  # one ray suffices: the range


def test_a_roof_lidar_sees_to_its_range():
    """CARLA's leaderboard lidar (its agent wrapper sets 64 channels from +10 to -30 deg, 85 m,
    600000 points a second at 10 Hz: 937 rays a channel, 0.384 deg) on a 2.5 m roof mount.
    Beside the mount its rays pass over a 1.5 m car (the lowest, -30 deg, is at 1.5 m only
    1.73 m out), which ended the sight at 0 m: the pass rule never held with a roof lidar.
    At 85 m: floor(1.9 / (85 m x 0.384 deg)) = 3 rays on each channel whose ray meets the
    car, those between atan(-2.5 / 85) = -1.68 deg and atan(-1 / 85) = -0.67 deg (the one at
    -0.79 deg): 85 m, the range."""
    roof = dict(rays=937, channels=64, vfov=math.radians(40.0), range=85.0, fov=2 * math.pi)
    mount = Extrinsics(z=2.5, pitch=math.radians(10.0))
    assert lidar_sight(roof, mount, 2) == 85.0
    # With a 200 m range: two rays a channel to 1.9 / (2 x 0.384 deg) = 141.67 m; beyond, one,
    # and the car's height spans 0.61 deg at 142 m, less than the 0.635 deg between channels.
    assert lidar_sight(dict(roof, range=200.0), mount, 2) == pytest.approx(141.5)
