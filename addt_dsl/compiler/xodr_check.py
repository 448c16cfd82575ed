"""Compile-time check of an imported `.xodr` file: it must parse, and the road id exist.

The road package is pure numpy (no pybullet or torch), so the compiler may use it to
turn OpenDRIVE errors into diagnostics at the `road ... import` line.
"""

from __future__ import annotations

from addt_dsl.diagnostics import Span


def check_xodr(ctx, text: str, display: str, span: Span, road_value) -> str | None:
    from addt_dsl.expr import eval_param_expr
    from addt_dsl.runtime.road import XodrError, parse_xodr

    try:
        network = parse_xodr(text, display)
    except XodrError as exc:
        where = f"{display}:{exc.line}" if getattr(exc, "line", None) else display
        ctx.sink.error("E0403", f"cannot use {display}: {exc.message if hasattr(exc, 'message') else exc}",
                       span, f"at {where}")
        return None
    if not network.roads:
        ctx.sink.error("E0403", f"{display} has no roads", span)
        return None
    if road_value is None:
        return next(iter(network.roads))
    road_id = str(int(eval_param_expr(road_value, {})))
    if road_id not in network.roads:
        ctx.sink.error("E0403", f"{display} has no road '{road_id}'", span,
                       f"roads: {', '.join(sorted(network.roads))}")
        return None
    return road_id
