"""Weather and light acting on sensor frames: the implementations of `addt_dsl/specs/environment.py`.

`environment { rain rate 10 mm/h; fog visibility 150 m; light sun 20 deg }` declares the
conditions of a scenario; each model changes the frames of the sensors it affects right
after capture (before faults), with random draws from the run's seeded generators. A
scenario without an environment block is clear daylight: no model runs, frames are
untouched. docs/twin.md states each model and its source.
"""

from __future__ import annotations

import dataclasses

import math

import numpy as np

from addt_dsl.kernel import exp
from addt_dsl.registry import ENVIRONMENTS
from addt_dsl.specs import environment as S

LIDAR_WAVELENGTH_NM = 905.0  # the common automotive lidar wavelength
KOSCHMIEDER = 3.912  # -ln(0.02): visibility at a 2 % contrast threshold


class EnvironmentModel(S.EnvironmentModelSpec):
    def __init__(self, settings: dict):
        self.settings = {p.name: settings.get(p.name, p.default) for p in self.params}

    def on_frame(self, sensor, frame, rng: np.random.Generator):
        """The frame as the conditions leave it (the same object if unaffected)."""
        return frame

    def friction_scale(self) -> float:
        """The factor on the tyre-road friction coefficient mu these conditions give."""
        return 1.0


def sun_elevation(time_s: float, latitude_rad: float, day: float) -> float:
    """The sun's elevation [rad] at local solar time `time_s` [s since midnight]: declination
    23.44 deg sin(360 deg (284 + day) / 365) (Cooper 1969), hour angle 15 deg per hour from
    noon, sin(el) = sin(lat) sin(dec) + cos(lat) cos(dec) cos(hour angle)."""
    dec = math.radians(23.44) * math.sin(2.0 * math.pi * (284.0 + day) / 365.0)
    hour_angle = (time_s / 3600.0 - 12.0) * math.radians(15.0)
    s = math.sin(latitude_rad) * math.sin(dec) + math.cos(latitude_rad) * math.cos(dec) * math.cos(hour_angle)
    return math.asin(max(-1.0, min(1.0, s)))


def lidar_detected(dist_m: np.ndarray, range_m: float, extinction_per_m: float) -> np.ndarray:
    """Returns still above the detection threshold after two-way attenuation: the lidar
    equation P ~ rho exp(-2 alpha d) / d^2, with the threshold that makes `range_m` the
    clear-air range, keeps a return iff d^2 exp(2 alpha d) <= range_m^2."""
    return dist_m * dist_m * exp.over(2.0 * extinction_per_m * dist_m) <= range_m * range_m


def _attenuate_lidar(sensor, frame, extinction_per_m: float, range_sigma_m: float, rng):
    pts = frame.data["points"]
    if not len(pts):
        return frame
    dist = np.linalg.norm(pts, axis=1)
    keep = lidar_detected(dist, sensor.range_m, extinction_per_m)
    pts, ids, dist = pts[keep], frame.data["hit_body"][keep], dist[keep]
    if range_sigma_m > 0.0 and len(pts):
        noisy = np.maximum(dist + rng.normal(0.0, range_sigma_m, len(dist)), 0.0)
        pts = pts * (noisy / np.maximum(dist, 1e-9))[:, None]
    data = dict(frame.data, points=pts, hit_body=ids)
    return dataclasses.replace(frame, data=data)  # (what was true at the capture stays)


def _fog_camera(frame, extinction_per_m: float, airlight: float):
    """Koschmieder's scattering: I = I0 exp(-alpha d) + A (1 - exp(-alpha d)) per pixel,
    with the depth the renderer gives."""
    image = frame.data["image"].astype(np.float32)
    trans = exp.over(-extinction_per_m * frame.data["depth"].astype(np.float32)).astype(np.float32)[..., None]
    out = image * trans + airlight * (1.0 - trans)
    data = dict(frame.data, image=np.clip(np.rint(out), 0, 255).astype(np.uint8))
    return dataclasses.replace(frame, data=data)  # (what was true at the capture stays)


@ENVIRONMENTS.implements
class Rain(S.Rain, EnvironmentModel):

    def extinction_per_m(self) -> float:
        """pi N0 / Lambda^3 [1/m]: extinction efficiency 2 over N(D) = N0 exp(-Lambda D),
        N0 = 8000 m^-3 mm^-1, Lambda = 4.1 R^-0.21 mm^-1 (Marshall and Palmer 1948)."""
        rate_mm_h = self.settings["rate"] * 3.6e6
        if rate_mm_h <= 0.0:
            return 0.0
        lam = 4.1 * rate_mm_h ** -0.21  # [1/mm]
        return math.pi * 8000.0 / lam ** 3 * 1e-6  # mm^2 m^-3 -> 1/m

    def on_frame(self, sensor, frame, rng):
        if sensor.keyword != "lidar":
            return frame
        return _attenuate_lidar(sensor, frame, self.extinction_per_m(), 0.0, rng)


@ENVIRONMENTS.implements
class Fog(S.Fog, EnvironmentModel):

    def q(self) -> float:
        """Kim's size-distribution exponent for visibility V [km]."""
        v = self.settings["visibility"] / 1000.0
        if v > 50.0:
            return 1.6
        if v > 6.0:
            return 1.3
        if v > 1.0:
            return 0.16 * v + 0.34
        if v > 0.5:
            return v - 0.5
        return 0.0

    def extinction_per_m(self, wavelength_nm: float = 550.0) -> float:
        return KOSCHMIEDER / self.settings["visibility"] * (wavelength_nm / 550.0) ** -self.q()

    def on_frame(self, sensor, frame, rng):
        if sensor.keyword == "lidar":
            return _attenuate_lidar(sensor, frame, self.extinction_per_m(LIDAR_WAVELENGTH_NM), 0.0, rng)
        if sensor.keyword == "camera":
            return _fog_camera(frame, self.extinction_per_m(), 200.0)
        return frame


@ENVIRONMENTS.implements
class Light(S.Light, EnvironmentModel):
    FULL_WELL_E = 10000.0
    READ_NOISE_E = 5.0
    MAX_GAIN = 8.0
    NIGHT_LEVEL = 0.02

    def elevation(self) -> float:
        """The sun's elevation [rad]: given, or from the time of day, latitude and day."""
        if self.settings["sun"] is not None:
            return self.settings["sun"]
        return sun_elevation(self.settings["time"], self.settings["latitude"], self.settings["day"])

    def ambient(self) -> float:
        level = math.sin(self.elevation()) / math.sin(math.radians(30.0))
        return min(1.0, max(self.NIGHT_LEVEL, level))

    def on_frame(self, sensor, frame, rng):
        if sensor.keyword != "camera":
            return frame
        k = self.ambient()
        if k >= 1.0:
            return frame  # full daylight: the rendered image is the exposure
        electrons = frame.data["image"].astype(np.float32) / 255.0 * self.FULL_WELL_E * k
        noisy = electrons + rng.normal(0.0, 1.0, electrons.shape).astype(np.float32) * np.sqrt(
            electrons + self.READ_NOISE_E ** 2)
        gain = min(1.0 / k, self.MAX_GAIN)
        out = noisy / self.FULL_WELL_E * 255.0 * gain
        data = dict(frame.data, image=np.clip(np.rint(out), 0, 255).astype(np.uint8))
        return dataclasses.replace(frame, data=data)  # (what was true at the capture stays)


@ENVIRONMENTS.implements
class Road(S.Road, EnvironmentModel):
    def friction_scale(self) -> float:
        return float(self.settings["friction"])


def friction_scale(models) -> float:
    """The product of the models' friction factors (1: none acts on friction)."""
    scale = 1.0
    for m in models:
        scale *= m.friction_scale()
    return scale
