"""Compile-time check of an imported `.xodr` file: it must parse, and the road id exist.

`addt_dsl.road` is pure numpy and defusedxml (no pybullet or torch; the layer
test checks it), so the compiler reads OpenDRIVE with the same code the runtime drives
on and turns its errors into diagnostics at the `road ... import` line.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import re
import threading

import numpy as np

from addt_dsl.compiler.context import Context, RoadInfo, const_value
from addt_dsl.diagnostics import Span
from addt_dsl.expr import eval_param_expr, params_used
from addt_dsl.limits import beyond_message, how_to_raise
from addt_dsl.lru import LruCache
from addt_dsl.road import RouteError, XodrError, parse_xodr, resolve_route
from addt_dsl.road.limits import RoadLimitError
from addt_dsl.road.roadspec import build_network


def check_xodr(ctx: Context, text: str, display: str, span: Span, road_value):
    """(road id, RoadInfo or None) of the imported road, or None after a diagnostic."""
    cache = ctx.xodr_networks  # one parse per file, however many roads import it
    if display not in cache and not _within_map_limits(ctx, text, display, span):
        return None
    try:
        network = cache.get(display) or cache.setdefault(display, parsed_map(text, display))
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
    if not _lanes_within_limit(ctx, network, display, span):
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
    info = road_info_of(network, road_id)
    if info is not None:
        info.network, info.road_id = network, road_id
    return road_id, info


# ---- maps parsed once per process (a suite's files import the same few maps)

MAP_CACHE_SIZE = 16
_INFOS: dict[int, dict[str, RoadInfo | None]] = {}  # id of a cached network -> RoadInfo per road id
_MAPS: LruCache[tuple[str, bytes], object] = LruCache(  # (display name, digest of the text) -> RoadNetwork
    MAP_CACHE_SIZE, on_evict=lambda network: _INFOS.pop(id(network), None))
_MAPS_LOCK = threading.RLock()


def parsed_map(text: str, display: str):
    """`parse_xodr(text, display)`, remembered within the process while the file's content
    is the same (the caller reads the file every time: an edited map is parsed again; the
    name is part of the key because error messages carry it). A map that does not parse
    raises every time. The network is only read afterwards (routes, road shapes), so
    compilations may share it; the runtime builds its own from the plan's text."""
    key = (display, hashlib.sha256(text.encode("utf-8", "surrogatepass")).digest())
    network = _MAPS.get(key)
    if network is not None:
        return network
    network = parse_xodr(text, display)
    with _MAPS_LOCK:
        _INFOS[id(network)] = {}
        _MAPS.put(key, network)
    return network


def road_info_of(network, road_id: str) -> RoadInfo | None:
    """`_road_info(network.road(road_id))`, computed once per road of a cached map (a
    fresh copy each time: callers fill in its network and id)."""
    with _MAPS_LOCK:
        infos = _INFOS.get(id(network))
        if infos is None:
            return _road_info(network.road(road_id))
        if road_id not in infos:
            infos[road_id] = _road_info(network.road(road_id))
        info = infos[road_id]
    return None if info is None else dataclasses.replace(info, lane_width_m=dict(info.lane_width_m))


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
    return roads, road_info_of(info.network, roads[0])


_COMMENT = re.compile(r"<!--.*?-->", re.S)
_ROAD_TAG = re.compile(r"<road[\s/>]")


def count_roads(text: str) -> int:
    """The <road> elements of an OpenDRIVE text, comments left out, without parsing it."""
    return sum(1 for _ in _ROAD_TAG.finditer(_COMMENT.sub("", text)))


def _within_map_limits(ctx: Context, text: str, display: str, span: Span) -> bool:
    """Count the map's <road> elements before building any (a 49 MB map of 129k roads took
    minutes to build): E0701 beyond `roads_per_map`. Comments are left out of the count."""
    limit = ctx.limits.roads_per_map
    roads = count_roads(text)
    if roads <= limit:
        return True
    ctx.sink.error("E0701", beyond_message(f"the number of roads in {display}", roads, "roads_per_map", limit),
                   span, how_to_raise("roads_per_map"))
    return False


def _lanes_within_limit(ctx: Context, network, display: str, span: Span) -> bool:
    limit = ctx.limits.lanes_per_section
    for road_id, road in network.roads.items():
        for k, section in enumerate(road.sections):
            lanes = len(section.lane_ids)
            if lanes > limit:
                ctx.sink.error("E0701", beyond_message(f"the lanes of road '{road_id}' section {k} in {display}",
                                                       lanes, "lanes_per_section", limit),
                               span, how_to_raise("lanes_per_section"))
                return False
    return True


def check_inline_road(ctx: Context, road_plan, span: Span) -> bool:
    """Build an inline road as every run will (same bounds as imported maps: total length,
    turn, samples), so a road no run could build is a compile error, not a crashed run.
    The verdict is a function of the road's plan alone, kept per process (suite files
    share their roads through included families)."""
    key = road_plan.model_dump_json()
    verdict = _INLINE.get(key)
    if verdict is None:
        verdict = _build_inline(road_plan)
        _INLINE.put(key, verdict)
    if verdict == ():
        return True
    ctx.sink.error(verdict[0], verdict[1], span)
    return False


INLINE_CACHE_SIZE = 256
_INLINE: LruCache[str, tuple] = LruCache(INLINE_CACHE_SIZE)  # RoadPlan JSON -> () when it builds, else (code, message)


def _build_inline(road_plan) -> tuple:
    try:
        build_network([road_plan])
    except RoadLimitError as exc:
        return "E0301", str(exc) if str(exc).startswith("road ") else f"road {road_plan.name}: {exc}"
    except (ValueError, ArithmeticError) as exc:
        return "E0204", f"road '{road_plan.name}' cannot be built: {exc}"
    return ()


def _road_info(road):
    """Length, lanes at s = 0 and the narrowest width of each lane along the road.

    Widths come from each section's own width polynomials (what `Road.lane_ids` and
    `Road.lane_width` evaluate), one pass per probe: linear in the number of lanes, where
    asking the road lane by lane re-derived every border per lane (quadratic)."""
    try:
        length = float(road.length)
        lanes = tuple(int(i) for i in road.lane_ids(0.0) if i != 0)
        wanted = set(lanes)
        widths: dict[int, float] = {}
        for s in np.linspace(0.0, length, 64):
            section = road.section_at(float(s))
            ds = float(s) - section.s0
            for lane_id in section.lane_ids:
                if lane_id not in wanted:
                    continue
                width = float(section.lane(lane_id).width(ds))
                if width > 1e-9:  # the lane exists here (Road.lane_ids' test)
                    widths[lane_id] = min(width, widths.get(lane_id, math.inf))
        return RoadInfo(length, lanes, widths)
    except (ValueError, ArithmeticError, KeyError, IndexError):
        return None
