"""Weather, light and road models' specs (`environment { rain ...; fog ...; light ...; road ... }`): keyword,
settings and docs; the models (acting on sensor frames, or on the ego's friction) are in
`addt_dsl/runtime/environment.py`."""

from __future__ import annotations

import math

from addt_dsl import units
from addt_dsl.registry import ENVIRONMENTS, ParamSpec


class EnvironmentModelSpec:
    keyword = ""
    params: tuple[ParamSpec, ...] = ()
    doc = ""


@ENVIRONMENTS.register
class Rain(EnvironmentModelSpec):
    keyword = "rain"
    params = (ParamSpec("rate", units.SPEED, required=True, low=0.0, high=200.0 * 1e-3 / 3600.0,
                        doc="rain rate (e.g. 2 mm/h light, 10 mm/h heavy, 50 mm/h a downpour)"),)
    doc = ("Lidar: extinction of the Marshall-Palmer drop sizes for drops much larger than the "
           "wavelength, 3.65e-4 R^0.63 per metre (R in mm/h), drops far returns by the lidar "
           "equation. Camera: not modelled.")

@ENVIRONMENTS.register
class Fog(EnvironmentModelSpec):
    keyword = "fog"
    params = (ParamSpec("visibility", units.LENGTH, required=True, low=10.0, high=100000.0,
                        doc="meteorological visibility (fog: below 1 km)"),)
    doc = ("Extinction from visibility V by Koschmieder (3.912 / V at 550 nm); lidar at 905 nm "
           "scaled by Kim et al. 2001 (lambda/550)^-q, returns dropped by the lidar equation; "
           "camera pixels blend towards the fog's airlight with their depth.")

@ENVIRONMENTS.register
class Light(EnvironmentModelSpec):
    keyword = "light"
    params = (ParamSpec("sun", units.ANGLE, low=-math.pi / 2, high=math.pi / 2,
                        doc="sun elevation above the horizon (below -6 deg: night); or give `time`"),
              ParamSpec("time", units.TIME, low=0.0, high=86400.0,
                        doc="local solar time of day since midnight (`6.5 h`): the sun's elevation follows "
                            "from it, `latitude` and `day`"),
              ParamSpec("latitude", units.ANGLE, default=math.radians(45.0), low=-math.pi / 2, high=math.pi / 2,
                        doc="where the sun is seen from, with `time`"),
              ParamSpec("day", None, default=80.0, low=1.0, high=366.0,
                        doc="day of the year, with `time` (80: the March equinox)"))
    doc = ("Camera exposure: ambient light k = sin(elevation)/sin(30 deg) in [0.02, 1] (0.02: a "
           "lit road at night); photon shot noise of a 10 000 e- full well plus 5 e- read noise, "
           "auto-gain up to 8x: darker, noisier, lower-contrast images. Lidar: active, unaffected. "
           "A time of day gives the elevation by the declination of Cooper (1969) and the hour angle.")

    @staticmethod
    def validate(values: dict) -> list[tuple[str, str]]:
        given = [key for key in ("sun", "time") if values.get(key, "absent") != "absent"]
        if not given:
            return [("sun", "`light` needs the sun's elevation (`sun 20 deg`) or a time of day (`time 6.5 h`)",
                     "E0105")]
        if len(given) > 1:
            return [("time", "give the sun's elevation or a time of day, not both", "E0204")]
        return []


@ENVIRONMENTS.register
class Road(EnvironmentModelSpec):
    keyword = "road"
    params = (ParamSpec("friction", units.DIMENSIONLESS, required=True, low=0.05, high=2.0,
                        doc="scale on the tyre-road friction coefficient (OpenSCENARIO's frictionScaleFactor; "
                            "0.5: a wet road, 0.1: ice)"),)
    doc = ("Vehicle dynamics: the ego's tyre forces saturate at friction x mu x Fz (Fiala brush model) from "
           "the moment the model acts; the stack's own braking limit keeps the declared mu (it is not told). "
           "Agents follow their scripts. Sensors: unaffected.")
