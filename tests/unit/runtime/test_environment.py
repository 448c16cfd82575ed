"""Weather and light models on sensor frames: each against its stated formula."""

import math

import numpy as np
import pytest

from addt_dsl.registry import ENVIRONMENTS
from addt_dsl.runtime.environment import KOSCHMIEDER, lidar_detected
from addt_dsl.runtime.sensors import Frame


class _Sensor:
    def __init__(self, keyword, range_m=80.0):
        self.keyword, self.range_m = keyword, range_m


def model(keyword, **settings):
    return ENVIRONMENTS.implementation(keyword)(settings)


def lidar_frame(distances):
    d = np.asarray(distances, dtype=float)
    pts = np.stack([d, np.zeros_like(d), np.zeros_like(d)], axis=1)
    return Frame("lidar", 0.0, {"points": pts, "hit_body": np.arange(len(d))})


def max_range(extinction, range_m=80.0):
    d = np.linspace(0.01, range_m, 200001)
    return d[lidar_detected(d, range_m, extinction)].max()


def test_clear_air_keeps_the_lidar_range():
    assert max_range(0.0) == pytest.approx(80.0)


@pytest.mark.parametrize("visibility,q", [(100000.0, 1.6), (20000.0, 1.3), (3000.0, 0.16 * 3 + 0.34),
                                          (800.0, 0.3), (200.0, 0.0)])
def test_fog_extinction_is_koschmieder_scaled_by_kim(visibility, q):
    fog = model("fog", visibility=visibility)
    assert fog.extinction_per_m() == pytest.approx(KOSCHMIEDER / visibility)
    assert fog.extinction_per_m(905.0) == pytest.approx(KOSCHMIEDER / visibility * (905.0 / 550.0) ** -q)


def test_denser_fog_drops_farther_returns_first():
    frame = lidar_frame([5.0, 20.0, 40.0, 70.0])
    kept = []
    for visibility in (2000.0, 200.0, 50.0):
        out = model("fog", visibility=visibility).on_frame(_Sensor("lidar"), frame, np.random.default_rng(0))
        kept.append(sorted(np.linalg.norm(out.data["points"], axis=1).round(6)))
        alpha = model("fog", visibility=visibility).extinction_per_m(905.0)
        assert kept[-1] == [d for d in (5.0, 20.0, 40.0, 70.0) if d * d * math.exp(2 * alpha * d) <= 6400.0]
    assert len(kept[0]) > len(kept[1]) > len(kept[2]) >= 1


def test_rain_extinction_follows_marshall_palmer():
    for rate in (1.0, 10.0, 50.0):
        rain = model("rain", rate=rate / 3.6e6)
        lam = 4.1 * rate ** -0.21
        assert rain.extinction_per_m() == pytest.approx(math.pi * 8000.0 / lam ** 3 * 1e-6)
    heavy = model("rain", rate=50.0 / 3.6e6).extinction_per_m()
    assert 0.5 * 80.0 < max_range(heavy) < max_range(model("rain", rate=2.0 / 3.6e6).extinction_per_m()) < 80.0


def test_rain_leaves_the_camera_and_light_leaves_the_lidar():
    frame = lidar_frame([10.0])
    assert model("light", sun=-0.5).on_frame(_Sensor("lidar"), frame, np.random.default_rng(0)) is frame
    cam = Frame("camera", 0.0, {"image": np.full((4, 4, 3), 100, np.uint8), "depth": np.ones((4, 4), np.float32)})
    assert model("rain", rate=1e-5).on_frame(_Sensor("camera"), cam, np.random.default_rng(0)) is cam


def _camera_frame(value=120, depth=30.0, size=64):
    return Frame("camera", 0.0, {"image": np.full((size, size, 3), value, np.uint8),
                                 "depth": np.full((size, size), depth, np.float32)})


def test_fog_blends_pixels_towards_the_airlight_with_depth():
    fog = model("fog", visibility=100.0)
    out = fog.on_frame(_Sensor("camera"), _camera_frame(value=40, depth=50.0), np.random.default_rng(0))
    t = math.exp(-KOSCHMIEDER / 100.0 * 50.0)
    assert out.data["image"][0, 0, 0] == round(40 * t + 200 * (1 - t))


def test_night_darkens_and_adds_noise_daylight_leaves_the_image():
    rng = np.random.default_rng(0)
    day = model("light", sun=math.radians(45.0))
    frame = _camera_frame()
    assert day.on_frame(_Sensor("camera"), frame, rng) is frame
    dusk = model("light", sun=math.radians(5.0)).on_frame(_Sensor("camera"), frame, rng).data["image"]
    night = model("light", sun=math.radians(-20.0)).on_frame(_Sensor("camera"), frame, rng).data["image"]
    # Night: ambient 0.02, auto-gain capped at 8: mean 120 * 0.16, noise amplified.
    assert night.mean() == pytest.approx(120 * 0.02 * 8, rel=0.05)
    # Less light: a lower signal-to-noise ratio (shot noise grows as the root of the light).
    assert night.mean() / night.std() < dusk.mean() / dusk.std() < math.inf
    assert dusk.std() > 0.0
