"""The vehicle catalogue: every actor kind's body, the one table the compiler (kinds and
default sizes), the twin (boxes, heights, colours), the stack (ego size, camera classes)
and the training data read."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class VehicleKind:
    length_m: float
    width_m: float
    height_m: float
    rgba: tuple[float, float, float, float]  # camera colour (the ego has no visual shape)


VEHICLES: dict[str, VehicleKind] = {
    "car": VehicleKind(4.6, 1.9, 1.5, (0.75, 0.12, 0.10, 1.0)),
    "truck": VehicleKind(12.0, 2.5, 3.5, (0.15, 0.30, 0.70, 1.0)),
    "pedestrian": VehicleKind(0.5, 0.5, 1.8, (0.90, 0.45, 0.70, 1.0)),
    "cyclist": VehicleKind(1.8, 0.6, 1.7, (0.95, 0.65, 0.10, 1.0)),
    # A static object (a box, a barrier, a broken-down car's stand-in): give `length`,
    # `width`; it does not move (speed 0, no behaviours).
    "obstacle": VehicleKind(1.0, 1.0, 1.0, (0.10, 0.60, 0.55, 1.0)),
}
# The dynamics of a vehicle the scenario leaves unset (every kind; the ego's `mass`,
# `wheelbase` and `mu` settings override them): the one place these defaults live.
DEFAULT_MASS_KG = 1500.0
DEFAULT_WHEELBASE_M = 2.7
DEFAULT_MU = 0.8  # tyre-road friction coefficient (dry asphalt)
STATIC_KINDS = frozenset({"obstacle"})  # kinds that never move
CAR = VEHICLES["car"]
