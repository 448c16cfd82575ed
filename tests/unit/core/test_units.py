import math

import pytest

from addt_dsl import units


@pytest.mark.parametrize("value,unit,si,dim", [
    (36, "km/h", 10.0, units.SPEED),
    (100, "ms", 0.1, units.TIME),
    (5, "%", 0.05, units.DIMENSIONLESS),
    (180, "deg", math.pi, units.ANGLE),
    (1, "mph", 0.44704, units.SPEED),
    (2, "km", 2000.0, units.LENGTH),
    (0.002, "/m", 0.002, units.CURVATURE),
    (3, "m/s^2", 3.0, units.ACCELERATION),
])
def test_to_si(value, unit, si, dim):
    got, got_dim = units.to_si(value, unit)
    assert got == pytest.approx(si)
    assert got_dim == dim


def test_dimension_algebra():
    assert units.LENGTH / units.TIME == units.SPEED
    assert units.SPEED / units.TIME == units.ACCELERATION
    assert units.dim_name(units.SPEED) == "speed"


def test_unknown_unit():
    with pytest.raises(units.UnknownUnit):
        units.to_si(1, "furlong")


def test_format_si_round_trips_exactly():
    text = units.format_si(0.1 + 0.2, units.LENGTH)
    assert float(text.split()[0]) == 0.1 + 0.2
