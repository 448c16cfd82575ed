"""Roads: inline geometry elements from the `GEOMETRIES` registry, or an imported `.xodr` road."""

from __future__ import annotations

from dataclasses import dataclass

from addt_dsl import plan as P
from addt_dsl.compiler import ast
from addt_dsl.compiler.context import Context, RoadInfo, check_settings, const_value, suggest
from addt_dsl.compiler.xodr_check import check_inline_road, check_xodr
from addt_dsl.registry import GEOMETRIES, ParamSpec


@dataclass(frozen=True)
class Roads:
    roads: list[P.RoadPlan]
    road_info: dict[str, RoadInfo]


def rule_roads(ctx: Context) -> Roads:
    out = Roads([], {})
    for d in ctx.roads_ast.values():
        got = _import_road(ctx, d) if d.import_path is not None else _inline_road(ctx, d)
        if got is not None:
            plan, info = got
            out.roads.append(plan)
            if info is not None:
                out.road_info[d.name] = info
    return out


def _inline_road(ctx: Context, d: ast.RoadDecl) -> tuple[P.RoadPlan, RoadInfo] | None:
    """Segments and lane layout from the `GEOMETRIES` registry, or None after a diagnostic."""
    segments, lanes, lanes_item, broken = [], None, None, False
    for item in d.items:
        cls = GEOMETRIES.get(item.kind)
        if cls is None:
            broken = True
            ctx.sink.error("E0106", f"unknown road element '{item.kind}'", item.span,
                           *suggest(item.kind, GEOMETRIES.names()),
                           f"road elements: {', '.join(GEOMETRIES.names())}")
            continue
        vals = check_settings(ctx, item.settings, cls.params, f"'{item.kind}'", item.span)
        if any(p.required and p.name not in vals for p in cls.params):
            broken = True
            continue  # reported by check_settings
        consts = {k: const_value(v) if not isinstance(v, str) else v for k, v in vals.items()}
        if any(v is None for v in consts.values()):
            broken = True
            ctx.sink.error("E0204", "road geometry must use constants, not parameters", item.span)
            continue
        spec = {p.name: p.default for p in cls.params}
        spec.update(consts)
        if not cls.is_segment:  # the lane layout
            if lanes is not None:
                ctx.sink.error("E0102", "lanes given twice", item.span, f"first given at {lanes_item.span}")
            lanes, lanes_item = spec, item
            continue
        if spec.get("length") is None:
            continue
        segments.append(cls.segment(spec))
    if not segments:
        if not broken:
            ctx.sink.error("E0103", f"road '{d.name}' has no geometry", d.span, "add e.g. `line length 500 m`")
        return None
    lanes = lanes or {p.name: p.default for p in GEOMETRIES.get("lanes").params}
    left, right = int(round(lanes["left"])), int(round(lanes["right"]))
    if left + right == 0:
        ctx.sink.error("E0204", f"road '{d.name}' has no lanes", lanes_item.span if lanes_item else d.span,
                       "e.g. `lanes right 2 width 3.5 m`")
        return None
    plan = P.RoadPlan(name=d.name, source="inline", segments=segments, left_lanes=left, right_lanes=right,
                      lane_width_m=lanes["width"], lane_offset_m=lanes["offset"])
    if not check_inline_road(ctx, plan, d.span):
        return None
    ids = tuple(range(left, 0, -1)) + tuple(range(-1, -right - 1, -1))
    return plan, RoadInfo(sum(s.length_m for s in segments), ids, {i: lanes["width"] for i in ids})


def _import_road(ctx: Context, d: ast.RoadDecl) -> tuple[P.RoadPlan, RoadInfo | None] | None:
    specs = (ParamSpec("road", None, kind="int", low=-(2**31), high=2**31 - 1,
                       doc="id of the road in the file to place actors on"),)
    vals = check_settings(ctx, d.import_settings, specs, "a road import", d.span)
    if not d.import_path.lower().endswith(".xodr"):
        ctx.sink.error("E0403", f"'{d.import_path}' is not an OpenDRIVE file", d.span,
                       "roads are imported from `.xodr` files")
        return None
    got = ctx.read_file(d.import_path, d.span) if ctx.read_file else None
    if got is None:
        return None
    display, text = got
    checked = check_xodr(ctx, text, display, d.span, vals.get("road"))
    if checked is None:
        return None
    road_id, info = checked
    return P.RoadPlan(name=d.name, source="xodr", xodr_file=display, xodr_text=text, xodr_road_id=road_id), info
