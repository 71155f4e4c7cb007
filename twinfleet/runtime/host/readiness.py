"""When a live node may run `@on_start`: its peers are alive and the fleet's time 0 is known.

A `NodeHost` declares its subscriptions, then waits: for the liveliness tokens
of the nodes it was told to wait for and, on a launched fleet, for the
launcher's epoch token (declared once every node is alive; its key carries
the epoch in ns). `Readiness` collects both as they arrive (Zenoh's callbacks,
on the loop) and `wait` returns once they are there, the run is stopped, or
the timeout passed (then the host starts anyway and says what was missing).
`time_zero` then moves the node's clock onto the epoch, so `@on_start` runs at
fleet time 0 as in the checker (a restarted node: at the time it restarted).
"""

from __future__ import annotations

import asyncio
from collections.abc import Sequence
from typing import Any, final

from twinfleet.runtime.host.keys import epoch_of


@final
class Readiness:
    """The peers seen alive and the fleet's epoch, for one node.

    Args:
        wait_for: node names whose liveliness tokens must be seen first.
        timeout_s: give up waiting after this many wall seconds.
        fleet_epoch: also wait for the launcher's epoch token.
    """

    def __init__(self, wait_for: Sequence[str], timeout_s: float, fleet_epoch: bool) -> None:
        self.wait_for, self.timeout_s, self.fleet_epoch = tuple(wait_for), timeout_s, fleet_epoch
        self.alive: set[str] = set()
        self.epoch_ns: int | None = None
        self.stopped = False
        self._changed: asyncio.Event | None = None

    def _wake(self) -> None:
        if self._changed is not None:
            self._changed.set()

    def node(self, name: str, alive: bool) -> None:
        """Node `name`'s liveliness token appeared (or went)."""
        (self.alive.add if alive else self.alive.discard)(name)
        self._wake()

    def epoch(self, key: str, alive: bool) -> None:
        """The launcher's epoch token (`keys.epoch_key`) appeared."""
        if alive:
            self.epoch_ns = epoch_of(key)
            self._wake()

    def stop(self) -> None:
        """End a `wait` at once (the node is stopping)."""
        self.stopped = True
        self._wake()

    def _ready(self) -> bool:
        return set(self.wait_for) <= self.alive and not (self.fleet_epoch
                                                         and self.epoch_ns is None)

    async def wait(self) -> str | None:
        """Wait until ready or stopped; what was still missing after the timeout, or None."""
        self._changed = asyncio.Event()
        loop = asyncio.get_running_loop()
        deadline = loop.time() + self.timeout_s
        while not self._ready() and not self.stopped:
            remaining = deadline - loop.time()
            if remaining <= 0:
                return ", ".join(sorted(set(self.wait_for) - self.alive)) or "the launcher's epoch"
            self._changed.clear()
            try:
                await asyncio.wait_for(self._changed.wait(), remaining)
            except TimeoutError:
                continue
        return None

    def time_zero(self, clock: Any, shift_arrivals: Any, restarted: bool) -> int:
        """The time `@on_start` runs at: 0 on the fleet's epoch when the launcher gave one
        (a `restarted` node: the fleet time it restarted at), else the clock's time.
        `shift_arrivals(ms)` moves what arrived before the epoch onto the new clock."""
        rebase = getattr(clock, "rebase", None)
        if self.epoch_ns is None or rebase is None:
            return clock.now_ms()
        before = clock.now_ms()
        rebase(self.epoch_ns)
        shift_arrivals(before - clock.now_ms())  # what came before time 0
        return clock.now_ms() if restarted else 0
