"""OpenDRIVE road geometry (pure numpy): planView primitives, lanes, road network.

Conventions: units are metres and radians; lane ids < 0 are right of the reference
line, > 0 left, 0 the centre lane; lateral offset ``t`` is positive to the left.
See docs/roads.md.
"""

from .geometry import (
    Arc,
    CubicProfile,
    Geometry,
    Line,
    ParamPoly3,
    Poly3,
    Spiral,
    arc,
    line,
    param_poly3,
    poly3,
    spiral,
)
from .lanes import Lane, LaneSection
from .network import (
    Connection,
    Junction,
    RoadCoords,
    RoadCoordsArray,
    RoadNetwork,
    build_road,
)
from .road import Controller, Road, RoadLink, Signal
from .route import TURNS, Leg, RouteError, describe_exits, exits, resolve_route, turn_of
from .xodr import XodrError, load_xodr, parse_xodr

__all__ = [
    "Arc", "CubicProfile", "Geometry", "Line", "ParamPoly3", "Poly3", "Spiral",
    "arc", "line", "param_poly3", "poly3", "spiral",
    "Lane", "LaneSection",
    "Connection", "Junction", "RoadCoords", "RoadCoordsArray", "RoadNetwork", "build_road",
    "Controller", "Road", "RoadLink", "Signal",
    "TURNS", "Leg", "RouteError", "describe_exits", "exits", "resolve_route", "turn_of",
    "XodrError", "load_xodr", "parse_xodr",
]
