"""Physical units and dimensions: the one place that knows what `km/h` means.

Every quantity in a `ScenarioPlan` is in SI (metres, seconds, radians, kilograms);
conversion happens once, in the compiler, through `to_si`. A dimension is a vector of
exponents over (length, time, mass, angle), so arithmetic in formulas
(`distance(ego, lead) / speed(ego)`) can be dimension-checked.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from fractions import Fraction


@dataclass(frozen=True, slots=True)
class Dim:
    """Exponents of length [m], time [s], mass [kg] and angle [rad]."""

    length: int = 0
    time: int = 0
    mass: int = 0
    angle: int = 0

    def __mul__(self, other: Dim) -> Dim:
        return Dim(self.length + other.length, self.time + other.time,
                   self.mass + other.mass, self.angle + other.angle)

    def __truediv__(self, other: Dim) -> Dim:
        return Dim(self.length - other.length, self.time - other.time,
                   self.mass - other.mass, self.angle - other.angle)

    def __str__(self) -> str:
        return dim_name(self)


DIMENSIONLESS = Dim()
LENGTH = Dim(length=1)
TIME = Dim(time=1)
MASS = Dim(mass=1)
ANGLE = Dim(angle=1)
SPEED = LENGTH / TIME
ACCELERATION = SPEED / TIME
JERK = ACCELERATION / TIME
FREQUENCY = DIMENSIONLESS / TIME
CURVATURE = DIMENSIONLESS / LENGTH
ANGULAR_RATE = ANGLE / TIME

# Names used in diagnostics and in registry parameter specs.
DIMENSION_NAMES: dict[Dim, str] = {
    DIMENSIONLESS: "number",
    LENGTH: "length",
    TIME: "time",
    MASS: "mass",
    ANGLE: "angle",
    SPEED: "speed",
    ACCELERATION: "acceleration",
    JERK: "jerk",
    FREQUENCY: "frequency",
    CURVATURE: "curvature",
    ANGULAR_RATE: "angular rate",
}
DIMENSIONS_BY_NAME: dict[str, Dim] = {v: k for k, v in DIMENSION_NAMES.items()}


def wrap_angle(angle_rad: float) -> float:
    """An angle [rad] wrapped into [-pi, pi)."""
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi


def dim_name(dim: Dim) -> str:
    """`speed`, `length`, ... or the units of an unnamed dimension, e.g. `m^2/s`."""
    named = DIMENSION_NAMES.get(dim)
    if named:
        return named
    num, den = [], []
    for symbol, exp in (("m", dim.length), ("kg", dim.mass), ("rad", dim.angle), ("s", dim.time)):
        if exp:
            part = symbol if abs(exp) == 1 else f"{symbol}^{abs(exp)}"
            (num if exp > 0 else den).append(part)
    text = "*".join(num) or "1"
    if den:
        text += "/" + ("*".join(den) if len(den) == 1 else "(" + "*".join(den) + ")")
    return f"quantity in {text}"


@dataclass(frozen=True, slots=True)
class Unit:
    symbol: str
    factor: float  # multiply a value in this unit by `factor` to get SI
    dim: Dim


_UNITS = (
    Unit("m", 1.0, LENGTH),
    Unit("km", 1000.0, LENGTH),
    Unit("cm", 0.01, LENGTH),
    Unit("mm", 0.001, LENGTH),
    Unit("s", 1.0, TIME),
    Unit("ms", 1e-3, TIME),
    Unit("min", 60.0, TIME),
    Unit("h", 3600.0, TIME),
    Unit("kg", 1.0, MASS),
    Unit("m/s", 1.0, SPEED),
    Unit("km/h", 1000.0 / 3600.0, SPEED),
    Unit("mph", 0.44704, SPEED),
    Unit("mm/h", 1e-3 / 3600.0, SPEED),  # rain rate
    Unit("m/s^2", 1.0, ACCELERATION),
    Unit("m/s^3", 1.0, JERK),
    Unit("g", 9.80665, ACCELERATION),
    Unit("Hz", 1.0, FREQUENCY),
    Unit("deg", math.pi / 180.0, ANGLE),
    Unit("rad", 1.0, ANGLE),
    Unit("deg/s", math.pi / 180.0, ANGULAR_RATE),
    Unit("rad/s", 1.0, ANGULAR_RATE),
    Unit("%", 0.01, DIMENSIONLESS),
    Unit("1/m", 1.0, CURVATURE),
    Unit("/m", 1.0, CURVATURE),
)
UNITS: dict[str, Unit] = {u.symbol: u for u in _UNITS}

# Canonical unit used when printing a quantity of a dimension back to source.
CANONICAL_UNIT: dict[Dim, str] = {
    LENGTH: "m", TIME: "s", MASS: "kg", SPEED: "m/s", ACCELERATION: "m/s^2",
    JERK: "m/s^3", FREQUENCY: "Hz", ANGLE: "rad", CURVATURE: "1/m",
    ANGULAR_RATE: "rad/s",
}


class UnknownUnit(KeyError):
    pass


def lookup(symbol: str) -> Unit:
    try:
        return UNITS[symbol]
    except KeyError:
        raise UnknownUnit(symbol) from None


def to_si(value: float, symbol: str | None) -> tuple[float, Dim]:
    """Convert `value` given in unit `symbol` (None: a plain number) to SI."""
    if symbol is None:
        return float(value), DIMENSIONLESS
    unit = lookup(symbol)
    return float(value) * unit.factor, unit.dim


def from_si(value_si: float, symbol: str) -> float:
    """An SI value in unit `symbol` (20 m/s -> 72 for `km/h`): the inverse of `to_si`."""
    return float(value_si) / lookup(symbol).factor


# A literal with more significant digits than this is float noise of arithmetic
# (`3.8000000000000003`, `13.88888888888889` for 50 km/h), not a value anyone wrote.
NOISE_DIGITS = 12


def significant_digits(text: str) -> int:
    """Significant digits of a decimal literal (`0.0012` -> 2, `1.5e-07` -> 2, `13.88888888888889` -> 16)."""
    mantissa = text.lower().lstrip("+-").split("e")[0].replace(".", "").lstrip("0")
    return len(mantissa.rstrip("0")) or 1


def decimal_fraction(value: float) -> Fraction:
    """A finite float as the decimal it reads as (its shortest repr: 0.1 -> 1/10), exactly."""
    return Fraction(repr(float(value)))


def decimal_sum(values: Iterable[float]) -> float:
    """The sum of numbers read from a file, as the decimals they were written as, rounded to
    a float once: 3.6 + 0.2 is 3.8 (float addition gives 3.8000000000000003, noise that
    would be printed back as written). Not finite: the float sum."""
    values = [float(v) for v in values]
    if not all(math.isfinite(v) for v in values):
        return math.fsum(values) if not any(math.isnan(v) for v in values) else math.nan
    return float(sum((decimal_fraction(v) for v in values), Fraction(0)))


def number_literal(value: float) -> str:
    """A float as source text that reads back bit for bit (repr; `1e999` for infinity)."""
    if math.isnan(value):
        raise ValueError("NaN has no surface syntax")
    if math.isinf(value):
        return "1e999" if value > 0 else "-1e999"  # overflows back to inf when read
    text = repr(float(value))
    return text[:-2] if text.endswith(".0") else text


def format_si(value: float, dim: Dim) -> str:
    """Render an SI value with its canonical unit, exactly (repr keeps every bit)."""
    unit = CANONICAL_UNIT.get(dim)
    text = repr(float(value))
    if text.endswith(".0"):
        text = text[:-2]
    return f"{text} {unit}" if unit else text


def dim_from_name(name: str) -> Dim:
    """Inverse of `dim_name`: `speed` → SPEED, `quantity in m*s` or `quantity in m^2/(s*kg)` → Dim."""
    if name in DIMENSIONS_BY_NAME:
        return DIMENSIONS_BY_NAME[name]
    if not name.startswith("quantity in "):
        raise ValueError(f"unknown dimension {name!r}")
    text = name[len("quantity in "):]
    num, _, den = text.partition("/")
    exps = {"m": 0, "kg": 0, "rad": 0, "s": 0}
    for part, sign in ((num, 1), (den.strip("()"), -1)):
        for factor in filter(None, part.split("*")):
            symbol, _, power = factor.partition("^")
            if symbol == "1":
                continue
            if symbol not in exps:
                raise ValueError(f"unknown dimension {name!r}")
            exps[symbol] += sign * int(power or 1)
    return Dim(exps["m"], exps["s"], exps["kg"], exps["rad"])
