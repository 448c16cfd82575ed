"""Compile-time check of an imported `.xodr` file: it must parse, and the road id exist.

`addt_dsl.runtime.road` is pure numpy and defusedxml (no pybullet or torch; the layer
test checks it), so the compiler reads OpenDRIVE with the same code the runtime drives
on and turns its errors into diagnostics at the `road ... import` line.
"""

from __future__ import annotations

import numpy as np

from addt_dsl.compiler.context import Context, RoadInfo, const_value
from addt_dsl.diagnostics import Span
from addt_dsl.expr import eval_param_expr, params_used
from addt_dsl.runtime.road import RouteError, XodrError, parse_xodr, resolve_route
from addt_dsl.runtime.road.limits import RoadLimitError
from addt_dsl.runtime.roadspec import build_network


def check_xodr(ctx: Context, text: str, display: str, span: Span, road_value):
    """(road id, RoadInfo or None) of the imported road, or None after a diagnostic."""
    cache = ctx.xodr_networks  # one parse per file, however many roads import it
    try:
        network = cache.get(display) or cache.setdefault(display, parse_xodr(text, display))
    except XodrError as exc:
        where = f"{display}:{exc.line}" if getattr(exc, "line", None) else display
        ctx.sink.error("E0403", f"cannot use {display}: {exc.message if hasattr(exc, 'message') else exc}",
                       span, f"at {where}")
        return None
    except (ValueError, ArithmeticError, RecursionError) as exc:  # geometry the reader accepted but cannot build
        ctx.sink.error("E0403", f"cannot use {display}: {exc}", span)
        return None
    if not network.roads:
        ctx.sink.error("E0403", f"{display} has no roads", span)
        return None
    if road_value is None:
        road_id = next(iter(network.roads))
    elif params_used(road_value):
        ctx.sink.error("E0204", "the imported road's id must be a constant, not a parameter", span)
        return None
    else:
        road_id = str(int(eval_param_expr(road_value, {})))
    if road_id not in network.roads:
        ctx.sink.error("E0403", f"{display} has no road '{road_id}'", span,
                       f"roads: {', '.join(sorted(network.roads))}")
        return None
    info = _road_info(network.road(road_id))
    if info is not None:
        info.network, info.road_id = network, road_id
    return road_id, info


def route_length(network, roads: list[str], lane) -> float:
    """Length [m] of an expanded route (its legs, from the first road's entry end)."""
    lane_c = const_value(lane)
    try:
        _, legs = resolve_route(network, roads, int(round(lane_c)) if lane_c is not None else -1)
    except RouteError:
        return float("inf")
    return sum(g.length_m for g in legs)


def check_route(ctx: Context, route, road_name: str, lane, s, lane_span: Span) -> tuple[list[str], object] | None:
    """Expand an actor's `route` on its imported road network: (road ids with the
    connecting roads, RoadInfo of the first road), or None after a diagnostic (E0404 with
    what the map offers where the route breaks)."""
    info = ctx.road_info.get(road_name)
    decl = ctx.roads_ast.get(road_name)
    if info is None and decl is not None and decl.import_path is not None:
        return None  # the import failed: reported there
    if info is None or info.network is None:
        ctx.sink.error("E0404", f"a route needs a road network imported from OpenDRIVE; '{road_name}' is inline",
                       route.span, "import a map: `road town import \"map.xodr\"`, then `route 1 -> left -> 3`")
        return None
    lane_c, s_c = const_value(lane), const_value(s)
    if lane_c is None:
        ctx.sink.error("E0204", "an actor with a route needs a constant lane", lane_span,
                       "lane ids differ from road to road; give the lane on the route's first road")
        return None
    try:
        roads, _ = resolve_route(info.network, list(route.stops), int(round(lane_c)), s_c)
    except RouteError as exc:
        span = route.stop_spans[min(exc.stop, len(route.stop_spans) - 1)]
        ctx.sink.error("E0404", exc.message, span, *([exc.hint] if exc.hint else []),
                       "routes are road ids in driving order, or turns at junctions: docs/roads.md, Routes")
        return None
    return roads, _road_info(info.network.road(roads[0]))


def check_inline_road(ctx: Context, road_plan, span: Span) -> bool:
    """Build an inline road as every run will (same bounds as imported maps: total length,
    turn, samples), so a road no run could build is a compile error, not a crashed run."""
    try:
        build_network([road_plan])
    except RoadLimitError as exc:
        message = str(exc) if str(exc).startswith("road ") else f"road {road_plan.name}: {exc}"
        ctx.sink.error("E0301", message, span)
        return False
    except (ValueError, ArithmeticError) as exc:
        ctx.sink.error("E0204", f"road '{road_plan.name}' cannot be built: {exc}", span)
        return False
    return True


def _road_info(road):
    """Length, lanes at s = 0 and the narrowest width of each lane along the road."""
    try:
        length = float(road.length)
        lanes = tuple(int(i) for i in road.lane_ids(0.0) if i != 0)
        widths = {}
        probe = np.linspace(0.0, length, 64)
        for lane in lanes:
            present = []
            for s in probe:
                if lane in road.lane_ids(float(s)):
                    present.append(float(road.lane_width(lane, float(s))))
            if present:
                widths[lane] = min(present)
        return RoadInfo(length, lanes, widths)
    except (ValueError, ArithmeticError, KeyError, IndexError):
        return None
