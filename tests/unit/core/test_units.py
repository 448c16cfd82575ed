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


def test_from_si_is_the_inverse_of_to_si():
    assert units.from_si(20.0, "km/h") == 72.0
    assert units.from_si(units.to_si(50, "km/h")[0], "km/h") == 50.0
    assert units.from_si(math.pi, "deg") == pytest.approx(180.0)


def test_no_km_per_hour_factor_outside_units():
    # km/h conversions go through `units` (to_si / from_si): no 3.6 (or 1000/3600) in code elsewhere.
    import io
    import tokenize
    from pathlib import Path

    package = Path(units.__file__).resolve().parent
    found = []
    for path in sorted(package.rglob("*.py")):
        if path.name == "units.py":
            continue
        tokens = list(tokenize.generate_tokens(io.StringIO(path.read_text()).readline))
        for k, tok in enumerate(tokens):
            if tok.type == tokenize.NUMBER and tok.string.replace("_", "").lower() in ("3.6", "3.60"):
                found.append(f"{path.relative_to(package)}:{tok.start[0]}")
            if tok.type == tokenize.NUMBER and tok.string in ("1000", "1000.0") and k + 2 < len(tokens) \
                    and tokens[k + 1].string == "/" and tokens[k + 2].string in ("3600", "3600.0"):
                found.append(f"{path.relative_to(package)}:{tok.start[0]}")
    assert found == []
