"""Inline road statements (`line`, `arc`, `spiral`, `param_poly3`, `lanes`) and the
builder that turns a `RoadPlan` into a road network.

Each geometry element is one registered class that knows its settings, the plan segment
its settings make (`segment`, the compiler), the settings a segment prints as
(`settings_of`, the printer; the inverse of `segment`) and the road geometry it builds
(`geometry`, the runtime). A new element is one class here.
"""

from __future__ import annotations

from addt_dsl import units
from addt_dsl.plan import RoadPlan, SegmentPlan
from addt_dsl.registry import GEOMETRIES, ParamSpec
from addt_dsl import road as R
from addt_dsl.road.limits import MAX_COORDINATE_M, MAX_ROAD_LENGTH_M


class RoadItemKind:
    keyword = ""
    params: tuple[ParamSpec, ...] = ()
    doc = ""
    is_segment = True  # a planView element (False: the lane layout)

    @classmethod
    def segment(cls, values: dict[str, float]) -> SegmentPlan:
        """The plan segment of checked settings (SI, defaults filled in)."""
        raise NotImplementedError

    @classmethod
    def settings_of(cls, seg: SegmentPlan) -> dict[str, float]:
        """The settings that make `seg` (every one, in `params` order)."""
        raise NotImplementedError

    @classmethod
    def geometry(cls, seg: SegmentPlan) -> R.Geometry:
        raise NotImplementedError


_LEN = ParamSpec("length", units.LENGTH, required=True, low=1e-3, high=MAX_ROAD_LENGTH_M,
                 doc="length along the reference line")


@GEOMETRIES.register
class LineItem(RoadItemKind):
    keyword = "line"
    params = (_LEN,)
    doc = "A straight reference line segment."

    @classmethod
    def segment(cls, values):
        return SegmentPlan(kind="line", length_m=values["length"])

    @classmethod
    def settings_of(cls, seg):
        return {"length": seg.length_m}

    @classmethod
    def geometry(cls, seg):
        return R.line(seg.length_m)


@GEOMETRIES.register
class ArcItem(RoadItemKind):
    keyword = "arc"
    params = (_LEN, ParamSpec("curvature", units.CURVATURE, required=True, low=-1.0, high=1.0,
                              doc="1/radius, positive turns left"))
    doc = "A constant-curvature segment."

    @classmethod
    def segment(cls, values):
        return SegmentPlan(kind="arc", length_m=values["length"], curvature_per_m=values["curvature"])

    @classmethod
    def settings_of(cls, seg):
        return {"length": seg.length_m, "curvature": seg.curvature_per_m}

    @classmethod
    def geometry(cls, seg):
        return R.arc(seg.length_m, seg.curvature_per_m)


@GEOMETRIES.register
class SpiralItem(RoadItemKind):
    keyword = "spiral"
    params = (_LEN,
              ParamSpec("from", units.CURVATURE, default=0.0, low=-1.0, high=1.0, doc="start curvature"),
              ParamSpec("to", units.CURVATURE, required=True, low=-1.0, high=1.0, doc="end curvature"))
    doc = "A clothoid: curvature changes linearly along the segment."

    @classmethod
    def segment(cls, values):
        return SegmentPlan(kind="spiral", length_m=values["length"], curv_start_per_m=values["from"],
                           curv_end_per_m=values["to"])

    @classmethod
    def settings_of(cls, seg):
        return {"length": seg.length_m, "from": seg.curv_start_per_m, "to": seg.curv_end_per_m}

    @classmethod
    def geometry(cls, seg):
        return R.spiral(seg.length_m, seg.curv_start_per_m, seg.curv_end_per_m)


@GEOMETRIES.register
class ParamPoly3Item(RoadItemKind):
    keyword = "param_poly3"
    params = (_LEN, *(ParamSpec(n, None, default=d, kind="number", low=-MAX_COORDINATE_M, high=MAX_COORDINATE_M,
                                doc=f"coefficient {n} [m]")
                      for n, d in (("au", 0.0), ("bu", 1.0), ("cu", 0.0), ("du", 0.0),
                                   ("av", 0.0), ("bv", 0.0), ("cv", 0.0), ("dv", 0.0))))
    doc = "A parametric cubic u(p), v(p) with p in [0, length] (pRange arcLength)."
    coefficients = ("au", "bu", "cu", "du", "av", "bv", "cv", "dv")

    @classmethod
    def segment(cls, values):
        return SegmentPlan(kind="param_poly3", length_m=values["length"],
                           coefficients=[values[k] for k in cls.coefficients])

    @classmethod
    def settings_of(cls, seg):
        return {"length": seg.length_m, **dict(zip(cls.coefficients, seg.coefficients))}

    @classmethod
    def geometry(cls, seg):
        return R.param_poly3(seg.length_m, *seg.coefficients)


@GEOMETRIES.register
class LanesItem(RoadItemKind):
    keyword = "lanes"
    params = (
        ParamSpec("right", None, kind="int", default=1, low=0, high=8, doc="lanes right of the reference line"),
        ParamSpec("left", None, kind="int", default=0, low=0, high=8, doc="lanes left of the reference line"),
        ParamSpec("width", units.LENGTH, default=3.5, low=1.0, high=10.0, doc="lane width"),
        ParamSpec("offset", units.LENGTH, default=0.0, low=-20.0, high=20.0, doc="lane offset"),
    )
    doc = "Lane layout of an inline road (one lane section, constant widths)."
    is_segment = False


def build_network(road_plans: list[RoadPlan]):
    """Build one `RoadNetwork` per road plan (imported files keep their own ids)."""
    networks = {}
    for rp in road_plans:
        if rp.source == "xodr":
            networks[rp.name] = R.parse_xodr(rp.xodr_text or "", rp.xodr_file or rp.name)
            continue
        segments = [GEOMETRIES.get(seg.kind).geometry(seg) for seg in rp.segments]
        networks[rp.name] = R.build_road(rp.name, segments, rp.left_lanes, rp.right_lanes,
                                         rp.lane_width_m, rp.lane_offset_m)
    return networks
