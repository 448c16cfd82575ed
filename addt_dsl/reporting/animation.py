"""Top-down animation of one run (opencv drawing, GIF via Pillow).

The camera follows the ego, north up. The road is drawn from the plan's road network
(asphalt band, solid outer borders, dashed lane borders); actors are their boxes from
the trace (ego blue, others orange, ego's recent path as a trail). Each failing oracle
is listed with its first violation time; from that time on the frame gets a red border
and the oracle is flagged VIOLATED, and the timeline at the bottom marks every violation
time. A violated `warn` oracle is flagged WARNING in amber and leaves the border alone.

A GIF (not a video file) because a browser shows it inline from a data URI with no
codec questions, which keeps the report a single self-contained file.
"""

from __future__ import annotations

import io
import math

import numpy as np

ROAD_SAMPLE_M = 1.0
DASH_M = 3.0

_BG = (58, 94, 52)  # BGR: grass
_ASPHALT = (70, 70, 70)
_LINE = (235, 235, 235)
_EGO = (200, 110, 30)
_AGENT = (40, 150, 240)
_RED = (40, 40, 220)
_AMBER = (0, 165, 255)
_TEXT = (255, 255, 255)


def road_geometry(plan) -> tuple[list[np.ndarray], list[np.ndarray], list[np.ndarray]]:
    """(asphalt polygons, solid polylines, dashed polylines) in world coordinates [m]."""
    from addt_dsl.road.roadspec import build_network

    polygons, solid, dashed = [], [], []
    for network in build_network(plan.roads).values():
        for road in network.roads.values():
            for sec in road.sections:
                s1 = min(sec.s1, road.length)
                if s1 - sec.s0 <= 1e-6:
                    continue
                s = np.linspace(sec.s0, s1 - 1e-6, max(2, int(math.ceil((s1 - sec.s0) / ROAD_SAMPLE_M)) + 1))
                lo, hi = road.road_band_t(s)
                left = np.stack(road.point_at(s, hi), axis=1)
                right = np.stack(road.point_at(s, lo), axis=1)
                polygons.append(np.concatenate([left, right[::-1]]))
                solid += [left, right]
                # Lane borders inside the band are dashed (the band's edges are drawn solid).
                right = sorted((i for i in sec.lane_ids if i < 0), reverse=True)  # -1, -2, ...
                left = sorted(i for i in sec.lane_ids if i > 0)  # 1, 2, ...
                for side in (right, left):
                    for lane in side[:-1]:
                        dashed.append(np.stack(road.point_at(s, road.lane_border_t(lane, s)[1]), axis=1))
                if right and left:
                    dashed.append(np.stack(road.point_at(s, road.lane_border_t(-1, s)[0]), axis=1))
    return polygons, solid, dashed


def _box(x: float, y: float, heading: float, length: float, width: float) -> np.ndarray:
    c, s = math.cos(heading), math.sin(heading)
    hl, hw = 0.5 * length, 0.5 * width
    corners = [(hl, hw), (hl, -hw), (-hl, -hw), (-hl, hw)]
    return np.array([(x + c * a - s * b, y + s * a + c * b) for a, b in corners])


class TopDownRenderer:
    def __init__(self, plan, width: int = 560, height: int = 300, px_per_m: float = 5.0):
        self.plan = plan
        self.width, self.height, self.ppm = width, height, px_per_m
        self.view_h = height - 26  # the bottom strip holds the timeline
        self.polygons, self.solid, self.dashed = road_geometry(plan)

    def _px(self, pts: np.ndarray, cx: float, cy: float) -> np.ndarray:
        u = self.width / 2 + (pts[:, 0] - cx) * self.ppm
        v = self.view_h / 2 - (pts[:, 1] - cy) * self.ppm
        return np.round(np.stack([u, v], axis=1) * 16).astype(np.int32)  # 4 fractional bits

    def frame(self, trace, k: int, violations: list[tuple[str, float, float, str]], label: str) -> np.ndarray:
        """`violations`: (oracle, first violation [s] or None, robustness, severity) of each failing oracle."""
        import cv2

        img = np.zeros((self.height, self.width, 3), np.uint8)
        img[: self.view_h] = _BG
        ego = trace.actors["ego"]
        cx, cy = float(ego.x[k]), float(ego.y[k])
        shift = 4
        for poly in self.polygons:
            cv2.fillPoly(img, [self._px(poly, cx, cy)], _ASPHALT, lineType=cv2.LINE_AA, shift=shift)
        for line in self.solid:
            cv2.polylines(img, [self._px(line, cx, cy)], False, _LINE, 2, cv2.LINE_AA, shift)
        step = max(1, int(round(DASH_M / ROAD_SAMPLE_M)))
        for line in self.dashed:
            px = self._px(line, cx, cy)
            segments = [px[i:i + step + 1] for i in range(0, len(px) - 1, 2 * step)]
            cv2.polylines(img, segments, False, _LINE, 1, cv2.LINE_AA, shift)
        trail = np.stack([ego.x[max(0, k - 500):k + 1], ego.y[max(0, k - 500):k + 1]], axis=1)
        if len(trail) > 1:
            cv2.polylines(img, [self._px(trail, cx, cy)], False, (240, 200, 120), 1, cv2.LINE_AA, shift)
        t_now = float(trace.time[k])
        violated = [v for v in violations if v[1] is not None and v[1] <= t_now + 1e-9]
        for name, track in trace.actors.items():
            box = _box(float(track.x[k]), float(track.y[k]), float(track.heading[k]), track.length_m,
                       track.width_m)
            colour = _EGO if name == "ego" else _AGENT
            pts = self._px(box, cx, cy)
            cv2.fillPoly(img, [pts], colour, cv2.LINE_AA, shift)
            touching = float(track.clearance[k]) <= 0.0
            cv2.polylines(img, [pts], True, _RED if touching else (20, 20, 20), 2 if touching else 1,
                          cv2.LINE_AA, shift)
            u, v = (pts.mean(axis=0) / 16).astype(int)
            cv2.putText(img, name, (int(u) + 8, int(v) - 8), cv2.FONT_HERSHEY_SIMPLEX, 0.35, _TEXT, 1, cv2.LINE_AA)
        # Header: run, time, failing oracles.
        cv2.rectangle(img, (0, 0), (self.width, 16 + 13 * len(violations)), (25, 25, 25), -1)
        cv2.putText(img, f"{label}   t = {t_now:5.2f} s", (6, 12), cv2.FONT_HERSHEY_SIMPLEX, 0.4, _TEXT, 1,
                    cv2.LINE_AA)
        for i, (name, first, rho, severity) in enumerate(violations):
            on = name in {v[0] for v in violated}
            warn = severity == "warn"
            when = f"{first:.2f} s" if first is not None else "-"
            state = ("WARNING" if warn else "VIOLATED") if on else ("warns" if warn else "fails")
            text = f"{state}: {name} at {when} (robustness {rho:.3g})"
            cv2.putText(img, text, (6, 25 + 13 * i), cv2.FONT_HERSHEY_SIMPLEX, 0.38,
                        (_AMBER if warn else (80, 80, 255)) if on else (200, 200, 200), 1, cv2.LINE_AA)
        if any(v[3] != "warn" for v in violated):
            cv2.rectangle(img, (1, 1), (self.width - 2, self.view_h - 2), _RED, 3)
        # Timeline with the violation times marked.
        t_end = max(float(trace.time[-1]), 1e-9)
        y0 = self.view_h + 8
        x0, x1 = 8, self.width - 8
        cv2.rectangle(img, (x0, y0), (x1, y0 + 8), (90, 90, 90), -1)
        cv2.rectangle(img, (x0, y0), (x0 + int((x1 - x0) * t_now / t_end), y0 + 8), (200, 200, 200), -1)
        for _, first, _, severity in violations:
            if first is not None:
                xv = x0 + int((x1 - x0) * min(first / t_end, 1.0))
                cv2.line(img, (xv, y0 - 4), (xv, y0 + 12), _AMBER if severity == "warn" else _RED, 2)
        return img


def frame_indices(trace, max_frames: int = 150, violation_times: tuple = (), frame_period_s: float = 0.1) -> list[int]:
    """Ticks every `frame_period_s` of simulated time (sparser if that gives more than
    `max_frames`), plus the tick of each first violation (so it is always shown)."""
    n = len(trace.time)
    if n == 0:
        return []
    step = max(1, int(round(frame_period_s / trace.period_s)), int(math.ceil(n / max_frames)))
    ks = set(range(0, n, step)) | {n - 1}
    for t in violation_times:
        if t is not None:
            ks.add(min(n - 1, max(0, int(round(t / trace.period_s)))))
    return sorted(ks)


def render_gif(plan, trace, verdicts, label: str = "", max_frames: int = 150, fps: float = 10.0,
               width: int = 560, height: int = 300) -> bytes:
    """GIF bytes of one run; `verdicts` are its oracle verdicts (the failing ones are marked)."""
    from PIL import Image

    failing = [(v.name, v.first_violation_s, v.robustness, v.severity) for v in verdicts if not v.passed]
    renderer = TopDownRenderer(plan, width, height)
    frames = [renderer.frame(trace, k, failing, label)
              for k in frame_indices(trace, max_frames, tuple(f[1] for f in failing))]
    images = [Image.fromarray(f[:, :, ::-1]).convert("P", palette=Image.Palette.ADAPTIVE, colors=32)
              for f in frames]
    buf = io.BytesIO()
    images[0].save(buf, format="GIF", save_all=True, append_images=images[1:],
                   duration=int(round(1000 / fps)), loop=0, optimize=False)
    return buf.getvalue()
