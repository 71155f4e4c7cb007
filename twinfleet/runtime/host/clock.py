"""Fleet time: milliseconds since the launcher's common epoch, optionally sped up.

`FleetClock(epoch_ns, time_scale)` is the live clock: every node of a fleet
gets the same `epoch_ns` from the launcher, so `now_ms()` agrees across
processes, and `time_scale=K` makes fleet time run K times faster than wall
time (timers fire K times sooner). `ManualClock` is the test double: time only
moves when the test calls `advance(ms)`, which fires due callbacks in order.

Both clocks schedule callbacks at absolute fleet times (`call_at`), which is
what makes periodic timers drift-free: a timer due at 300 ms reschedules
itself at 400 ms, whatever the lateness of the 300 ms firing.
"""

from __future__ import annotations

import asyncio
import heapq
import itertools
import time
from collections.abc import Callable
from typing import Any, Protocol, final


class TimerHandle(Protocol):
    """What `call_at` returns: something that can be cancelled."""

    def cancel(self) -> None:
        """Prevent the callback from running, if it has not run yet."""
        ...


class Clock(Protocol):
    """The host's view of time: read it, and schedule callbacks at fleet times."""

    def now_ms(self) -> int:
        """Fleet milliseconds since the common epoch."""
        ...

    def call_at(self, due_ms: int, fn: Callable[..., Any], *args: Any) -> TimerHandle:
        """Run `fn(*args)` on the loop when fleet time reaches `due_ms`."""
        ...

    def real_seconds(self, fleet_ms: float) -> float:
        """Wall-clock seconds that `fleet_ms` of fleet time last."""
        ...


_time_ns = time.time_ns


@final
class FleetClock:
    """Live fleet time shared by every process of a fleet.

    Args:
        epoch_ns: `time.time_ns()` at the fleet's start (chosen by the launcher).
        time_scale: fleet milliseconds per wall millisecond (K > 1 runs faster).
    """

    def __init__(self, epoch_ns: int | None = None, time_scale: float = 1.0) -> None:
        if time_scale <= 0:
            raise ValueError(f"time_scale must be > 0, got {time_scale}")
        self.epoch_ns = time.time_ns() if epoch_ns is None else int(epoch_ns)
        self.time_scale = float(time_scale)
        self._ns_per_ms = 1e6 / self.time_scale  # exactly 1e6 at scale 1: same value as before

    def rebase(self, epoch_ns: int) -> None:
        """Take `epoch_ns` as fleet time 0 from now on (the launcher's, once all are alive)."""
        self.epoch_ns = int(epoch_ns)

    def _now_precise(self) -> float:
        return (_time_ns() - self.epoch_ns) / self._ns_per_ms

    def now_ms(self) -> int:
        """Fleet milliseconds since the epoch (floored); read for every message: one expression."""
        return int((_time_ns() - self.epoch_ns) / self._ns_per_ms)

    def real_seconds(self, fleet_ms: float) -> float:
        """Wall seconds corresponding to `fleet_ms` fleet milliseconds."""
        return fleet_ms / 1000.0 / self.time_scale

    def call_at(self, due_ms: int, fn: Callable[..., Any], *args: Any) -> TimerHandle:
        """Schedule `fn(*args)` on the running loop at fleet time `due_ms`."""
        delay = max(0.0, self.real_seconds(due_ms - self._now_precise()))
        return asyncio.get_running_loop().call_later(delay, fn, *args)


@final
class _ManualHandle:
    __slots__ = ("cancelled",)

    def __init__(self) -> None:
        self.cancelled = False

    def cancel(self) -> None:
        self.cancelled = True


@final
class ManualClock:
    """A clock for tests: time advances only through `advance(ms)`.

    Callbacks due at the same time run in the order they were scheduled.
    """

    def __init__(self, start_ms: int = 0) -> None:
        self._now = start_ms
        self._heap: list[tuple[int, int, _ManualHandle, Callable[..., Any], tuple[Any, ...]]] = []
        self._counter = itertools.count()

    def now_ms(self) -> int:
        """The current manual time."""
        return self._now

    def real_seconds(self, fleet_ms: float) -> float:
        """Manual time has no wall-clock meaning; durations map 1:1 to seconds/1000."""
        return fleet_ms / 1000.0

    def call_at(self, due_ms: int, fn: Callable[..., Any], *args: Any) -> TimerHandle:
        """Schedule `fn(*args)` to run when `advance` reaches `due_ms`."""
        handle = _ManualHandle()
        heapq.heappush(self._heap, (max(due_ms, self._now), next(self._counter), handle, fn, args))
        return handle

    def pending(self) -> int:
        """How many scheduled callbacks have not run or been cancelled."""
        return sum(1 for entry in self._heap if not entry[2].cancelled)

    def next_due(self) -> int | None:
        """Fleet time of the earliest pending callback, or None."""
        while self._heap and self._heap[0][2].cancelled:
            heapq.heappop(self._heap)
        return self._heap[0][0] if self._heap else None

    def advance(self, ms: int) -> int:
        """Move time forward by `ms`, running every callback that falls due; return how many ran."""
        target = self._now + ms
        ran = 0
        while self._heap and self._heap[0][0] <= target:
            due, _, handle, fn, args = heapq.heappop(self._heap)
            if handle.cancelled:
                continue
            self._now = due
            fn(*args)
            ran += 1
        self._now = target
        return ran
