"""What a `checker.search.Search` holds, and how it is saved and stopped.

`SearchState` keeps the visited store, the frontier, the counters and the clocks of one
search, makes its statistics, writes it to a `checker.checkpoint` file and reads it back,
and turns an early stop into an `Outcome` that can be resumed (a half-expanded world put
back first). How the search explores is `Search`'s, which builds on this.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable, Mapping
from typing import Any

from twinfleet.checker import checkpoint
from twinfleet.checker.growth import GrowthWatch
from twinfleet.checker.outcome import (
    NO_LIMITS,
    Counterexample,
    Counters,
    Guard,
    Limits,
    Outcome,
    SearchStatistics,
    peak_rss_mb,
)
from twinfleet.checker.properties import PropertySet, PropertyViolation
from twinfleet.checker.reduction import Reduction
from twinfleet.checker.store import StateStore
from twinfleet.checker.system import System
from twinfleet.checker.transition import Transition
from twinfleet.checker.world import World
from twinfleet.runtime.contract.kinds import Status

FORGET_EVERY = 512  # expansions between two `System.forget_before` calls (at least)


class SearchState:
    """The state of one search over a `System` for a `PropertySet`.

    Args:
        system: the compiled scenario.
        properties: what to check.
        limits: state, time and depth limits.
        progress: called with statistics at most every `progress_interval` seconds.
        checkpoint: file to save the search to (periodically and when it stops early).
        checkpoint_every_s: seconds between periodic checkpoints.
        checkpoint_meta: what the checkpoint must record to be resumed (scenario, options).
        handle_sigint: stop cleanly on the first Ctrl-C (main thread only).
        reduction: expand worlds by persistent sets (`checker.reduction`); None: fully.
    """

    def __init__(self, system: System, properties: PropertySet, limits: Limits = NO_LIMITS, *,
                 progress: Callable[[SearchStatistics], None] | None = None,
                 progress_interval: float = 1.0, checkpoint: str | None = None,
                 checkpoint_every_s: float = 300.0,
                 checkpoint_meta: Mapping[str, Any] | None = None,
                 handle_sigint: bool = True, reduction: Reduction | None = None) -> None:
        self.system = system
        self.reduction = reduction
        self.properties = properties
        self.guard = Guard(limits, progress, progress_interval, handle_sigint)
        self._max_states = limits.max_states  # read once per new state
        live = tuple(p.name for p in properties.eventually)
        self.store = StateStore(exact=system.exact_states, record_edges=bool(live), flags=live)
        self.counters = Counters()
        self.growth = GrowthWatch(system.names, system.decode)
        self._frontier: deque[tuple[World, int, int]] = deque()
        self._expansions = 0
        self._next_forget = FORGET_EVERY
        self._pruned = False
        self._resumed = False
        self._elapsed_before = 0.0
        self._attempt: float | None = None  # when the search last started again (monotonic)
        self._aside: str | None = None  # why the reduction stepped aside (`Search`)
        # the initial transitions, built once: a restart starts from them again, and
        # building them runs every start handler (head-on: 0.7 ms a pass)
        self._initial: list[Transition] | None = None
        self._hashed_before = 0  # content hashes of the searches this one continues
        self._expanding: tuple[World, int, int] | None = None
        self._expanded_from = 0  # `counters.transitions` when `_expanding` began
        # BFS: the depth being expanded and the largest id of a world at most that deep
        self._level: tuple[int, int] = (-1, -1)
        self._checkpoint = checkpoint
        self._checkpoint_every = checkpoint_every_s
        self._checkpoint_meta = dict(checkpoint_meta or {})
        self._lifo = False
        self._strategy = "bfs"
        self._last_checkpoint = time.monotonic()

    @property
    def limits(self) -> Limits:
        """The search's limits (may be replaced before `run`)."""
        return self.guard.limits

    @limits.setter
    def limits(self, limits: Limits) -> None:
        self.guard.limits = limits
        self._max_states = limits.max_states

    def statistics(self) -> SearchStatistics:
        """The counters so far."""
        store, c = self.store, self.counters
        hashed = 0 if store.exact else self.system.hashed + self._hashed_before
        now = time.monotonic()  # one reading: the attempt never outlasts the elapsed time
        return SearchStatistics(
            len(store), c.transitions, c.initial, c.depth, len(self._frontier),
            self._elapsed_before + now - self.guard.started, peak_rss_mb(),
            store.nbytes(), store.digest_bits, store.collision_probability(hashed),
            c.peak_frontier,
            # an attempt begun before the search's clock started (a restart while the search
            # was set up) counts from the clock's start, as the elapsed time does
            None if self._attempt is None else now - max(self._attempt, self.guard.started),
            0 if self.reduction is None else self.reduction.stats.restarts,
            growth=self.growth.notes())

    def _stopped(self, reason: str, *, clean: bool) -> Outcome:
        """An early stop: put back a half-expanded world, then save a checkpoint if asked.

        `Stop` is only raised where the store is consistent (between expansions,
        or right after a state was added), so the world being expanded can be put
        back and expanded again on resume: it re-finds the successors already
        added as known states, in the same order.
        """
        saved = None
        if clean and self._expanding is not None:
            self.counters.transitions = self._expanded_from
            if self._lifo:
                self._frontier.append(self._expanding)
            else:
                self._frontier.appendleft(self._expanding)
            self._expanding = None
        if clean and self._checkpoint is not None and self._strategy != "random":
            self.save(self._checkpoint)
            saved = self._checkpoint
        outcome = self._outcome(Status.UNKNOWN, reason)
        outcome.checkpoint = saved
        return outcome

    def _outcome(self, status: Status, reason: str, violation: PropertyViolation | None = None,
                 counterexample: Counterexample | None = None) -> Outcome:
        return Outcome(status, reason, self.statistics(), violation, counterexample)

    # ------------------------------------------------------ checkpoints

    def save(self, path: str) -> None:
        """Write the search (store, frontier, counters) to `path` atomically."""
        c = self.counters
        counters = {"transitions": c.transitions, "initial": c.initial, "depth": c.depth,
                    "pruned": self._pruned, "peak_frontier": c.peak_frontier,
                    "elapsed": self._elapsed_before + time.monotonic() - self.guard.started,
                    "hashed": self.system.hashed + self._hashed_before,
                    "strategy": "dfs" if self._lifo else "bfs", "level": self._level,
                    "publications": self.system.publications.__getstate__(),
                    "visibility": None if self.reduction is None else
                    (self.reduction.visibility.rising, self.reduction.visibility.fell,
                     self.reduction.visibility.pending_fall),
                    "reduction": None if self.reduction is None else self.reduction.stats,
                    "waiting": self.reduction is not None and self.reduction.waiting,
                    "aside": self._aside,
                    "relied": [] if self.reduction is None else sorted(self.reduction.relied)}
        checkpoint.save(path, self._checkpoint_meta, self.store, list(self._frontier), counters)
        self._last_checkpoint = time.monotonic()

    def restore(self, data: Mapping[str, Any]) -> None:
        """Continue from a loaded checkpoint (`checker.checkpoint.load`)."""
        self.store = data["store"]
        self._frontier = deque(data["frontier"])
        c = data["counters"]
        self.counters = Counters(c["transitions"], c["initial"], c["depth"], c["peak_frontier"])
        self._pruned = c["pruned"]
        self._level = tuple(c.get("level", (-1, -1)))
        self._elapsed_before = c["elapsed"]
        self._hashed_before = c["hashed"]
        if "publications" in c:  # what the reduced search so far relied on
            self.system.publications.__setstate__(c["publications"])
        if self.reduction is not None and c.get("reduction") is not None:
            self.reduction.stats, self.reduction.waiting = c["reduction"], c.get("waiting", False)
            self.reduction.relied = set(c.get("relied", ()))
        if self.reduction is not None and c.get("visibility") is not None:
            visibility = self.reduction.visibility
            visibility.rising, visibility.fell, visibility.pending_fall = c["visibility"]
        if self.reduction is not None and c.get("aside"):
            self.reduction.aside, self._aside = c["aside"], c["aside"]
            self.reduction = None
        self._resumed = True

    def _reset(self) -> None:
        """Forget everything explored (a restart of a reduced search)."""
        self.store = StateStore(exact=self.store.exact, record_edges=self.store.edges is not None,
                                flags=tuple(self.store.holds))
        self.counters = Counters()
        self.growth = GrowthWatch(self.system.names, self.system.decode)
        self._frontier.clear()
        self._expansions = 0
        self._next_forget = FORGET_EVERY
        self._pruned = False
        self._resumed = False
        self._level = (-1, -1)
        self._attempt = time.monotonic()
