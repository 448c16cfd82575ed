"""Weather and light models' specs (`environment { rain ...; fog ...; light ... }`): keyword,
settings and docs; the models that change sensor frames are in `addt_dsl/runtime/environment.py`."""

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
    params = (ParamSpec("sun", units.ANGLE, required=True, low=-math.pi / 2, high=math.pi / 2,
                        doc="sun elevation above the horizon (below -6 deg: night)"),)
    doc = ("Camera exposure: ambient light k = sin(elevation)/sin(30 deg) in [0.02, 1] (0.02: a "
           "lit road at night); photon shot noise of a 10 000 e- full well plus 5 e- read noise, "
           "auto-gain up to 8x: darker, noisier, lower-contrast images. Lidar: active, unaffected.")
