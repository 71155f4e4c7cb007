"""How often Python's cyclic garbage collector runs during a search.

A search keeps millions of small containers alive for as long as it runs
(worlds, cached handler outcomes, what a reduction derives from its relation),
and CPython's default thresholds walk all of them again and again: a reduced
search of C1a with 0-1 ms of latency made 11 full collections in 30 s in one
process (8-18 % of its time) and 65 in a worker that held its own copy of the
system (28 %; docs/performance.md). What a search allocates forms next to no
reference cycles (1,667 objects collected in those 30 s), so it asks for a
collection a hundred times less often; cycles are still collected, later.
"""

from __future__ import annotations

import gc
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Final

# Allocations before a young collection (default 700), young collections before a middle
# one, middle ones before a full one is considered (defaults 10, 10).
SEARCH_THRESHOLDS: Final = (50_000, 20, 20)


@contextmanager
def seldom_collections() -> Iterator[None]:
    """Collect cycles seldom while the block runs (a search); the thresholds before
    come back after it."""
    before = gc.get_threshold()
    gc.set_threshold(*SEARCH_THRESHOLDS)
    try:
        yield
    finally:
        gc.set_threshold(*before)
