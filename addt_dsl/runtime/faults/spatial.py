"""Sensor spatial faults: a moved mount (shift, drift) and additive noise on the data."""

from __future__ import annotations

import math

import numpy as np

from addt_dsl.kernel import matmul
from addt_dsl.registry import FAULTS
from addt_dsl.specs import faults as S
from addt_dsl.runtime.faults.base import FaultKind

_AXES = S._AXES


@FAULTS.implements
class Shift(S.Shift, FaultKind):

    def __init__(self, *a):
        super().__init__(*a)
        self._offset = {ax: float(self.settings[ax]) for ax in _AXES}
        self._state = "before"  # before → drifting → full

    def before_capture(self, sensor, time_s):
        if time_s < self.start:
            return
        ramp = float(self.settings["ramp"])
        k = 1.0 if ramp <= 0 else min(1.0, (time_s - self.start) / ramp)
        sensor.actual = sensor.nominal.shifted(**{ax: k * v for ax, v in self._offset.items()})
        state = "full" if k >= 1.0 else "drifting"
        if state != self._state:
            self._state = state
            self.record(time_s, sensor.name, {ax: k * v for ax, v in self._offset.items() if v},
                        ramp_s=ramp, fraction=k)


@FAULTS.implements
class Noise(S.Noise, FaultKind):

    def on_frame(self, frame, time_s):
        if not self.active(time_s):
            return frame, 0.0
        data = frame.data
        if "points" in data:
            frame.data = self._lidar(data, frame.sensor, time_s)
        elif "x" in data and "y" in data:
            sigma = float(self.settings["position"])
            dx, dy = self.rng.normal(0.0, sigma, 2) if sigma > 0 else (0.0, 0.0)
            frame.data = {**data, "x": data["x"] + dx, "y": data["y"] + dy}
            self.record(time_s, frame.sensor, math.hypot(dx, dy), dx=dx, dy=dy)
        return frame, 0.0

    def _lidar(self, data: dict, sensor: str, time_s: float) -> dict:
        pts = data["points"]
        n = len(pts)
        out = dict(data)
        sigma, dropout = float(self.settings["range"]), float(self.settings["dropout"])
        rms = 0.0
        if sigma > 0 and n:
            r = np.sqrt(pts[:, 0] * pts[:, 0] + pts[:, 1] * pts[:, 1] + pts[:, 2] * pts[:, 2])
            noise = self.rng.normal(0.0, sigma, n)
            # Move each point along its ray; a return cannot come from behind the sensor.
            scale = np.maximum(r + noise, 0.0)
            scale /= np.maximum(r, 1e-9)
            pts = pts * scale[:, None]
            rms = math.sqrt(float(matmul(noise, noise)) / n)
        lost = 0
        if dropout > 0 and n:
            keep = self.rng.random(n) >= dropout
            kept = np.flatnonzero(keep)
            lost = n - len(kept)
            if lost:
                pts = pts[kept]
                for k, v in out.items():  # per-return arrays (hit bodies, ...) lose the same rows
                    if isinstance(v, np.ndarray) and len(v) == n and k != "points":
                        out[k] = v[kept]
        out["points"] = pts
        self.record(time_s, sensor, rms, returns_lost=lost, returns=n)
        return out
