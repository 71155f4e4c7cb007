"""A bounded cache with two generations, for handler outcomes (`checker.system`).

Entries live in a young and an old dict. New entries go to the young one;
when it holds `limit` entries it becomes the old one and the previous old one
is dropped, so at most 2 × `limit` entries are kept. A hit in the old
generation moves the entry back to the young one: what the search keeps
using survives, what it stopped using is dropped after at most two turns.
Keys end with an absolute time, so `forget_before` can also drop every entry
no world left to expand can use.
"""

from __future__ import annotations

from typing import Any, Generic, TypeVar, final

V = TypeVar("V")


@final
class GenerationCache(Generic[V]):
    """Keys are tuples whose last item is a time in ms; at most 2 × `limit` entries."""

    def __init__(self, limit: int) -> None:
        if limit < 1:
            raise ValueError(f"limit must be positive, got {limit}")
        self.limit = limit
        self._young: dict[tuple[Any, ...], V] = {}
        self._old: dict[tuple[Any, ...], V] = {}

    def __len__(self) -> int:
        return len(self._young) + len(self._old)

    def get(self, key: tuple[Any, ...]) -> V | None:
        """The value cached for `key`, or None."""
        found = self._young.get(key)
        if found is None:
            found = self._old.pop(key, None)
            if found is not None:
                self.put(key, found)
        return found

    def put(self, key: tuple[Any, ...], value: V) -> None:
        """Cache `value` for `key` (turning the generations over when the young one is full)."""
        if len(self._young) >= self.limit:
            self._old = self._young
            self._young = {}
        self._young[key] = value

    def forget_before(self, time_ms: int) -> int:
        """Drop the entries whose key ends with a time before `time_ms`; return how many."""
        dropped = 0
        for gen in (self._young, self._old):
            dead = [k for k in gen if k[-1] < time_ms]
            for k in dead:
                del gen[k]
            dropped += len(dead)
        return dropped
