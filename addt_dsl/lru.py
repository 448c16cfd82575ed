"""`LruCache`: the bounded, thread-safe, least-recently-used cache of the project.

Where `functools.lru_cache` fits (a pure function of hashable arguments) it is used; this
class is for the caches it does not fit: a value kept only when its computation reported
nothing (included files), a key that is a digest of the argument rather than the argument
(maps, inline roads), or something to drop with an evicted value (`on_evict`).
The value is computed outside the lock by the caller: two threads may compute the same
value at once, and the last one stored wins (every value stored under a key is equal).
"""

from __future__ import annotations

import threading
from typing import Callable, Generic, Hashable, TypeVar

K = TypeVar("K", bound=Hashable)
V = TypeVar("V")


class LruCache(Generic[K, V]):
    def __init__(self, size: int, on_evict: Callable[[V], None] | None = None):
        self.size = size
        self.on_evict = on_evict
        self._data: dict[K, V] = {}  # insertion order = least recently used first
        self._lock = threading.RLock()

    def get(self, key: K) -> V | None:
        """The value under `key`, now the most recently used; None when there is none."""
        with self._lock:
            value = self._data.pop(key, None)
            if value is not None:
                self._data[key] = value
            return value

    def put(self, key: K, value: V) -> None:
        """Keep `value` as the most recently used; drop the least recently used beyond `size`."""
        with self._lock:
            self._data.pop(key, None)
            self._data[key] = value
            while len(self._data) > self.size:
                evicted = self._data.pop(next(iter(self._data)))
                if self.on_evict is not None:
                    self.on_evict(evicted)

    def __len__(self) -> int:
        return len(self._data)

    def __contains__(self, key: K) -> bool:
        return key in self._data
