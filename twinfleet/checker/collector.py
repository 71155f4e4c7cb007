"""How often Python's cyclic garbage collector runs during a search.

A search keeps millions of small containers alive for as long as it runs
(worlds, cached handler outcomes, what a reduction derives from its relation),
and CPython's default thresholds walk all of them again and again: a reduced
search of C1a with 0-1 ms of latency made 11 full collections in 30 s in one
process (8-18 % of its time) and 65 in a worker that held its own copy of the
system (28 %; docs/performance.md). What a search allocates forms next to no
reference cycles (1,667 objects collected in those 30 s), so it asks for a
collection a hundred times less often; cycles are still collected, later.

Both switches here are process-wide, so each is set for a block of work and the value
before comes back after it: `seldom_collections`, `quick_switches` (how soon a thread
waiting for the interpreter gets it), and `Held` for an object that works across many
calls (a cluster worker: from its start until it is released).
"""

from __future__ import annotations

import gc
import sys
from collections.abc import Iterator
from contextlib import AbstractContextManager, ExitStack, contextmanager
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


@contextmanager
def quick_switches(seconds: float) -> Iterator[None]:
    """Let a thread waiting for the interpreter have it after `seconds` (Python's switch
    interval) while the block runs; the interval before comes back after it."""
    before = sys.getswitchinterval()
    sys.setswitchinterval(seconds)
    try:
        yield
    finally:
        sys.setswitchinterval(before)


class Held:
    """Process-wide settings held for an object's work across many calls: `hold` enters
    them, `release` restores what was there before (again: nothing)."""

    _held: ExitStack | None = None

    def hold(self, *settings: AbstractContextManager[None]) -> None:
        """Enter `settings` until `release`."""
        if self._held is None:
            self._held = ExitStack()
        for setting in settings:
            self._held.enter_context(setting)

    def release(self) -> int:
        """Restore every setting held, the last entered first (returns 0: a Ray call's
        answer)."""
        if self._held is not None:
            self._held.close()
        return 0
