"""Per-node latency models: deterministic by default, measured in HIL-like mode.

A model is `base_s + per_object_s * objects`, calibrated from measured compute times and
stored as data in `latency_model.json` (the paper's Jetson-class budget: perception
dominates and grows with the object count).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

MODEL_PATH = Path(__file__).with_name("latency_model.json")


@dataclass(frozen=True)
class LatencyModel:
    base_s: float
    per_object_s: float

    def latency(self, objects: int) -> float:
        return self.base_s + self.per_object_s * objects


def load_models(path: Path = MODEL_PATH) -> dict[str, LatencyModel]:
    data = json.loads(path.read_text())
    return {node: LatencyModel(float(v["base_s"]), float(v["per_object_s"]))
            for node, v in data["nodes"].items()}
