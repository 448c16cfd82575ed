"""Per-node latency: a measured trend, measured jitter, and an explicit target scaling.

`latency_model.json` holds, per node, what `python -m addt_dsl.stack.calibrate --write`
measured on the host: the trend `base_s + per_object_s * N + per_object_sq_s * N²` for N
objects (through the medians per object count) and the jitter, a table of quantiles of
`sample / median at that object count` over all the timed calls (pooled over counts). Its
`targets` are hand-written inputs, never fitted: the factors that carry host costs to a
target (`host`: 1 and 1; `xavier`: a Jetson AGX Xavier-class board, each factor with its
source or stated as an assumption). A node's latency in a run is

    (base_s * f_base + (per_object_s * N + per_object_sq_s * N²) * cpu_scale) * ratio

with `f_base` the target's `accelerator_scale` for perception (its network runs on the
board's GPU) and `cpu_scale` otherwise, and `ratio` drawn from the jitter table by
inverse-CDF sampling with a numpy generator seeded from the run seed and the node name,
so a run repeats bit for bit. Nothing is timed during a run.
"""

from __future__ import annotations

import bisect
import functools
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from addt_dsl.kernel import bisect_right, kernel
from addt_dsl.lru import LruCache
from addt_dsl.specs.stacks import DEFAULT_LATENCY_TARGET, LATENCY_MODEL_PATH, latency_targets

MODEL_PATH = LATENCY_MODEL_PATH
NODES = ("perception", "tracker", "planner", "control")
DEFAULT_TARGET = DEFAULT_LATENCY_TARGET


@dataclass(frozen=True)
class LatencyModel:
    """One node's latency on one target: trend [s] and jitter (quantiles of the ratio to it)."""

    base_s: float
    per_object_s: float
    levels: tuple[float, ...]  # cumulative probabilities, increasing, from 0
    ratios: tuple[float, ...]  # the ratio sample / median at each level, non-decreasing
    per_object_sq_s: float = 0.0  # pairwise work (the tracker's association) [s per object²]

    def median(self, objects: int) -> float:
        """The trend [s]: the median latency with `objects` objects."""
        return self.base_s + (self.per_object_s + self.per_object_sq_s * objects) * objects

    def ratio(self, u: float) -> float:
        """Inverse CDF of the jitter ratio at `u` in [0, 1): piecewise linear between the
        stored quantiles; above the last level (p99.9) it stays at the last quantile."""
        lv, r = self.levels, self.ratios
        i = bisect.bisect_right(lv, u)
        if i >= len(lv):
            return r[-1]
        lo, hi = lv[i - 1], lv[i]
        return r[i - 1] + (r[i] - r[i - 1]) * (u - lo) / (hi - lo)

    def quantile(self, objects: int, p: float) -> float:
        """The latency [s] at probability `p` with `objects` objects."""
        return self.median(objects) * self.ratio(p)

    def ratios_at(self, u: np.ndarray) -> np.ndarray:
        """`ratio` over an array of probabilities (np.interp: the same piecewise-linear
        inverse CDF, constant above the last level)."""
        return np.interp(u, self.levels, self.ratios)

    def ratios_of(self, u: np.ndarray) -> np.ndarray:
        """`ratio` of each of `u`'s probabilities (float64), its arithmetic in one kernel call:
        the same bits."""
        out = np.empty(len(u))
        _ratios_of(self._table[0], self._table[1], u, out)
        return out

    @functools.cached_property
    def _table(self) -> tuple[np.ndarray, np.ndarray]:
        return np.array(self.levels, dtype=np.float64), np.array(self.ratios, dtype=np.float64)

    def sample(self, objects: int, rng: np.random.Generator) -> float:
        """One latency [s] with `objects` objects, drawn with `rng` (one uniform per call)."""
        return self.median(objects) * self.ratio(float(rng.random()))


@kernel
def _ratios_of(levels, ratios, u, out):
    """`LatencyModel.ratio` of each u into `out`, written as it is."""
    n = len(levels)
    for k in range(len(u)):
        x = u[k]
        i = bisect_right(levels, x, n)
        if i >= n:
            out[k] = ratios[n - 1]
        else:
            lo, hi = levels[i - 1], levels[i]
            out[k] = ratios[i - 1] + (ratios[i] - ratios[i - 1]) * (x - lo) / (hi - lo)


class Jitter:
    """One node's latencies in a run: its model's trend times a jitter ratio, the ratios of its
    generator's uniforms taken 64 at a time (numpy's `random(n)` fills an array with what n
    calls give, `ratios_of` gives `ratio`'s bits): `sample` gives what `LatencyModel.sample`
    with a call of the generator each gives, at a fifth of its cost."""

    __slots__ = ("model", "rng", "_block", "_i")
    BLOCK = 64

    def __init__(self, model: LatencyModel, rng: np.random.Generator):
        self.model, self.rng = model, rng
        self._block: list[float] = []
        self._i = 0

    def sample(self, objects: int) -> float:
        """The next latency [s] with `objects` objects."""
        i = self._i
        if i == len(self._block):
            self._block, i = self.model.ratios_of(self.rng.random(self.BLOCK)).tolist(), 0
        self._i = i + 1
        return self.model.median(objects) * self._block[i]


def read(path: Path = MODEL_PATH) -> dict:
    return json.loads(path.read_text())


target_names = latency_targets  # the `latency_target` setting's choices


# Parsed models per (target, file and its version): parsing the file cost ~7 ms a run.
_MODELS: LruCache[tuple, dict[str, LatencyModel]] = LruCache(8)


def load_models(target: str = DEFAULT_TARGET, path: Path = MODEL_PATH, data: dict | None = None
                ) -> dict[str, LatencyModel]:
    """Per-node models scaled to `target` (a name in the file's `targets`)."""
    if data is None:
        stat = path.stat()
        key = (target, str(path), stat.st_mtime_ns, stat.st_size)
        models = _MODELS.get(key)
        if models is None:
            models = _scaled(target, read(path))
            _MODELS.put(key, models)
        return dict(models)  # (the models are frozen; the dict is the caller's)
    return _scaled(target, data)


def _scaled(target: str, data: dict) -> dict[str, LatencyModel]:
    t = data["targets"][target]
    levels = tuple(float(v) for v in data["jitter_levels"])
    models = {}
    for node, v in data["nodes"].items():
        f_base = float(t["accelerator_scale"]) if node == "perception" else float(t["cpu_scale"])
        cpu = float(t["cpu_scale"])
        models[node] = LatencyModel(float(v["base_s"]) * f_base, float(v["per_object_s"]) * cpu,
                                    levels, tuple(float(r) for r in v["jitter_ratios"]),
                                    float(v.get("per_object_sq_s", 0.0)) * cpu)
    return models


def pipeline_ms(lat_s: dict[str, float]) -> float:
    """Sum of the node latencies [ms]."""
    return 1e3 * sum(lat_s[n] for n in NODES)


def e2e_ms(lat_s: dict[str, float], step_s: float) -> float:
    """End-to-end latency [ms] the `bev` stack records for a frame arriving on a step, given
    each node's latency [s].

    The bus delivers a message at the first physics step at or after its publish time:
    perception's objects reach the tracker, the tracks reach the planner (which runs on
    fresh tracks), and the plan's publish time minus the sensor stamp plus the control
    latency is `e2e`.
    """
    def next_step(t: float) -> float:
        return math.ceil(t / step_s - 1e-9) * step_s

    tracks_at = next_step(next_step(lat_s["perception"]) + lat_s["tracker"])
    return 1e3 * (tracks_at + lat_s["planner"] + lat_s["control"])


def at(models: dict[str, LatencyModel], objects: int, p: float | None = None) -> dict[str, float]:
    """Each node's latency [s] with `objects` objects: the median trend, or the quantile at
    probability `p` (control's cost does not depend on the object count)."""
    out = {}
    for n, m in models.items():
        k = 0 if n == "control" else objects
        out[n] = m.median(k) if p is None else m.quantile(k, p)
    return out


def e2e_quantile_ms(models: dict[str, LatencyModel], objects: int, p: float, step_s: float,
                    draws: int = 20000, seed: int = 0) -> float:
    """The e2e latency [ms] at probability `p` when every node draws its own jitter, as in
    a run (nodes independent), estimated from `draws` Monte Carlo samples with a fixed
    seed: the same uniforms for every object count, so the figure grows with it."""
    u = np.random.default_rng(seed).random((len(NODES), draws))
    lat = {n: models[n].median(0 if n == "control" else objects) * models[n].ratios_at(u[i])
           for i, n in enumerate(NODES)}
    tracks_at = np.ceil((np.ceil(lat["perception"] / step_s - 1e-9) * step_s + lat["tracker"]) / step_s - 1e-9) * step_s
    return float(1e3 * np.quantile(tracks_at + lat["planner"] + lat["control"], p))


def crossing(models: dict[str, LatencyModel], limit_ms: float, step_s: float, p: float | None = None,
             max_objects: int = 5000) -> int | None:
    """The fewest objects whose e2e latency exceeds `limit_ms`: with every node at its
    median, or at probability `p` of the e2e distribution (`e2e_quantile_ms`); None if
    not within `max_objects`. Both grow with the object count: bisection."""
    def over(n: int) -> bool:
        e2e = e2e_ms(at(models, n), step_s) if p is None else e2e_quantile_ms(models, n, p, step_s)
        return e2e > limit_ms

    if not over(max_objects):
        return None
    lo, hi = -1, max_objects  # over(lo) false (or lo = -1), over(hi) true
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (lo, mid) if over(mid) else (mid, hi)
    return hi
