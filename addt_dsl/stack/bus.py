"""A tiny ROS-like bus in simulated time.

A message carries the sensor timestamp it derives from (`stamp_s`) and becomes visible
at `deliver_s` (publish time + latency). Delivery order is (deliver_s, sequence), so it
is deterministic.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass, field
from typing import Any


@dataclass(order=True)
class Message:
    deliver_s: float
    seq: int
    topic: str = field(compare=False)
    stamp_s: float = field(compare=False)
    data: Any = field(compare=False)


class Bus:
    def __init__(self):
        self._queue: list[Message] = []
        self._seq = 0
        self.latest: dict[str, Message] = {}
        self.next_s = math.inf  # when the next message is delivered [s] (inf: none waits)

    def publish(self, topic: str, data: Any, stamp_s: float, deliver_s: float) -> None:
        self._seq += 1
        heapq.heappush(self._queue, Message(deliver_s, self._seq, topic, stamp_s, data))
        self.next_s = self._queue[0].deliver_s

    def due(self, time_s: float) -> bool:
        """Whether a message is delivered by `time_s` [s] (`deliver_until` returns some)."""
        return self.next_s <= time_s + 1e-12

    def deliver_until(self, time_s: float) -> list[Message]:
        """Pop every message due by `time_s`, in delivery order; remember the latest per topic."""
        out = []
        queue = self._queue
        while queue and queue[0].deliver_s <= time_s + 1e-12:
            msg = heapq.heappop(queue)
            self.latest[msg.topic] = msg
            out.append(msg)
        self.next_s = queue[0].deliver_s if queue else math.inf
        return out
