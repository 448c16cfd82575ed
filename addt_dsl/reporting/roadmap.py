"""`addtc map FILE.xodr`: what a user needs to write routes, without reading XML.

`describe(network)` lists roads (length, traffic rule, links at both ends), their lanes
per lane section with type and driving direction (`+s` along the reference line, `-s`
against it), junctions with every connection (the turn it makes, the road it leads to,
its lane links) and signals. `map_png(network)` draws the map with road, junction and
signal ids (matplotlib, Agg backend).
"""

from __future__ import annotations

import io
import math

import numpy as np

from addt_dsl.road import RoadNetwork, exits, turn_of


def _key(text: str):
    return (0, int(text), "") if text.lstrip("-").isdigit() else (1, 0, text)


def _link(link) -> str:
    if link is None:
        return "-"
    if link.element_type == "junction":
        return f"junction {link.element_id}"
    return f"road {link.element_id} ({link.contact_point or 'start'})"


def _count(n: int, what: str) -> str:
    return f"{n} {what}" + ("" if n == 1 else "s")


def describe(network: RoadNetwork, name: str = "") -> str:
    roads = sorted(network.roads.values(), key=lambda r: _key(r.id))
    lines = [f"{name or network.source_name}: {_count(len(roads), 'road')}, "
             f"{_count(len(network.junctions), 'junction')}, {_count(sum(len(r.signals) for r in roads), 'signal')}",
             "lanes: id type direction (+s: traffic along the road's s, -s: against it)", ""]
    for road in roads:
        inside = f", in junction {road.junction}" if road.junction not in ("-1", "") else ""
        lines.append(f"road {road.id}{f' {road.name!r}' if road.name else ''}: {road.length:.1f} m, "
                     f"{road.rule}{inside}; start: {_link(road.predecessor)}; end: {_link(road.successor)}")
        for sec in road.sections:
            lanes = ", ".join(f"{i} {sec.lane(i).type} {'+s' if road.travel_direction(i) > 0 else '-s'}"
                              for i in sec.lane_ids)
            lines.append(f"  s {sec.s0:.1f}-{sec.s1:.1f} m: {lanes}")
    for jid in sorted(network.junctions, key=_key):
        junction = network.junctions[jid]
        lines += ["", f"junction {jid}{f' {junction.name!r}' if junction.name else ''}:"]
        for c in junction.connections:
            links = ", ".join(f"{a}->{b}" for a, b in c.lane_links) or "no lane links"
            if c.direct:
                lines.append(f"  {c.id}: road {c.incoming_road} -> road {c.connecting_road} (direct; lanes {links})")
                continue
            if c.connecting_road not in network.roads:
                lines.append(f"  {c.id}: road {c.incoming_road} -> {c.connecting_road} (missing road)")
                continue
            after = [e.road_id for e in exits(network, c.connecting_road, "end" if c.contact_point == "start"
                                              else "start")]
            turn = turn_of(network, c.connecting_road, c.contact_point)
            lines.append(f"  {c.id}: road {c.incoming_road} -> {c.connecting_road} {turn} -> "
                         f"road {', '.join(after) or '?'} (lanes {links})")
    signals = [(road, sg) for road in roads for sg in road.signals]
    if signals:
        lines += ["", "signals:"]
        for road, sg in signals:
            kind = "traffic light" if sg.dynamic else "sign"
            lines.append(f"  {sg.id}{f' {sg.name!r}' if sg.name else ''}: road {road.id} s {sg.s:.1f} m "
                         f"t {sg.t:.1f} m, {kind}, type {sg.type or '-'}/{sg.subtype or '-'}, "
                         f"facing {sg.orientation}"
                         + (f", lanes {sg.validity[0]}..{sg.validity[1]}" if sg.validity else ""))
    if network.controllers:  # signals that switch together: `controller C id ID` in `lights { }`
        lines += ["", "controllers:"]
        for c in network.controllers.values():
            lines.append(f"  {c.id}{f' {c.name!r}' if c.name else ''}: signals {', '.join(c.signal_ids) or '-'}")
    return "\n".join(lines) + "\n"


def map_png(network: RoadNetwork, title: str = "") -> bytes:
    """A top view of every road (lane band, driving-lane centres with direction arrows)
    with road ids, junction ids and signal ids drawn on it."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(10, 10), dpi=100)
    spans = []
    for road in network.roads.values():
        s = np.linspace(0.0, road.length, max(2, int(math.ceil(road.length / 1.0)) + 1))
        lo, hi = road.road_band_t(s)
        x, y, h = road.reference_pose(s)
        in_junction = road.junction not in ("-1", "")
        colour = "#c98b2b" if in_junction else "#555555"
        for t in (lo, hi):
            ax.plot(x - np.sin(h) * t, y + np.cos(h) * t, color=colour, lw=0.6)
        spans.append((x.min(), x.max(), y.min(), y.max()))
        mid = len(s) // 2
        for lane in road.driving_lane_ids(float(s[mid])):
            tc = float(road.lane_center_t(lane, float(s[mid])))
            px, py = float(x[mid] - math.sin(h[mid]) * tc), float(y[mid] + math.cos(h[mid]) * tc)
            d = road.travel_direction(lane)
            ax.annotate("", xy=(px + d * 2.0 * math.cos(h[mid]), py + d * 2.0 * math.sin(h[mid])), xytext=(px, py),
                        arrowprops=dict(arrowstyle="->", color=colour, lw=0.8))
        if not in_junction:
            ax.text(float(x[mid]), float(y[mid]), road.id, fontsize=9, color="#1f4e9c", weight="bold",
                    ha="center", va="center", bbox=dict(boxstyle="round,pad=0.15", fc="white", ec="none", alpha=0.8))
        for sg in road.signals:
            sx, sy, sh = (float(v) for v in road.reference_pose(sg.s))
            ax.plot(sx - math.sin(sh) * sg.t, sy + math.cos(sh) * sg.t, "o", ms=3,
                    color="#c0392b" if sg.dynamic else "#7f8c8d")
            ax.text(sx - math.sin(sh) * sg.t, sy + math.cos(sh) * sg.t, f" {sg.id}", fontsize=6, color="#c0392b")
    for junction in network.junctions.values():
        pts = [network.road(c.connecting_road).reference_pose(network.road(c.connecting_road).length / 2)
               for c in junction.connections if c.connecting_road in network.roads and not c.direct]
        if pts:
            jx, jy = float(np.mean([p[0] for p in pts])), float(np.mean([p[1] for p in pts]))
            ax.text(jx, jy, f"J{junction.id}", fontsize=8, color="#c98b2b", weight="bold", ha="center")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title or network.source_name, fontsize=9)
    ax.grid(alpha=0.2)
    buf = io.BytesIO()
    fig.tight_layout()
    fig.savefig(buf, format="png")
    plt.close(fig)
    return buf.getvalue()
