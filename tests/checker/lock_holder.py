"""A module-level lock, and a batch function that reports whether it can take it
(tests/checker/test_parallel.py)."""

from __future__ import annotations

import threading

LOCK = threading.Lock()


def lock_is_free(batch: list[int]) -> list[bool]:
    """One answer per index: whether this process could take `LOCK` within 2 s."""
    free = LOCK.acquire(timeout=2)
    if free:
        LOCK.release()
    return [free for _ in batch]
